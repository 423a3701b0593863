"""Pictures of paths-form plans: floor layout (PNG), Gantt chart (PNG), animated run (GIF).

Inputs are the plain JSON dicts of the wire format (request, response, optional
world), so this package imports nothing else from the service. It needs
matplotlib (and Pillow, which matplotlib already requires): the ``pictures``
extra. ``python -m service.pictures`` writes all three from saved JSON files.
"""

from service.pictures.animation import write_gif
from service.pictures.gantt import draw_gantt
from service.pictures.layout import draw_layout

__all__ = ["draw_layout", "draw_gantt", "write_gif"]
