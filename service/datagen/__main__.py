"""``python -m service.datagen``: build or resume a dataset (see :mod:`service.datagen.build`)."""

from service.datagen.build import main

if __name__ == "__main__":
    main()
