#!/usr/bin/env bash
# Build the scheduler's image with podman, start it, check it answers, stop it.
#
#   deploy/build-image.sh            # base image (once), wheels, image, smoke test
#   SMOKE=0 deploy/build-image.sh    # build only
#
# No image registry is reachable from these machines, so the base image is made from
# Debian packages: debootstrap a minimal bookworm (python3 3.11, venv) and podman import
# it. Every Python dependency is downloaded as a wheel into deploy/wheels with the
# host's pip (its index and the CPU torch wheel), so the image build needs no network.
# Needs root, podman and debootstrap (apt-get install podman debootstrap).
set -euo pipefail
cd "$(dirname "$0")/.."

BASE=${BASE:-localhost/scheduler-base:bookworm}
IMAGE=${IMAGE:-localhost/coordination-scheduler:latest}
MIRROR=${DEBIAN_MIRROR:-http://deb.debian.org/debian}
PORT=${SMOKE_PORT:-18000}
READY_TIMEOUT_S=${READY_TIMEOUT_S:-180}

build_base() {
    # A minimal Debian with Python 3.11 (bookworm's python3), imported as an image.
    local rootfs
    rootfs=$(mktemp -d)
    trap 'rm -rf "$rootfs"' RETURN
    debootstrap --variant=minbase --include=python3,python3-venv,ca-certificates \
        bookworm "$rootfs" "$MIRROR"
    rm -rf "$rootfs"/var/cache/apt/archives/*.deb "$rootfs"/var/lib/apt/lists/*
    tar -C "$rootfs" -c . | podman import --change 'CMD ["python3"]' - "$BASE"
}

build_wheels() {
    # The project and every dependency as wheels (CPU torch pinned, found by the host's pip).
    rm -rf deploy/wheels
    python -m pip wheel --quiet --wheel-dir deploy/wheels torch==2.13.0 .
}

start_container() {
    # Start the image in the background as $CONTAINER, serving on $PORT of the host network.
    # Where crun may not set resource limits (inside a container sandbox: "setrlimit:
    # Operation not permitted"), podman run cannot start it; buildah then runs the same
    # image, as its user and with its environment, with chroot isolation instead.
    if podman run -d --rm --name "$CONTAINER" --network host -e SCHEDULER_PORT="$PORT" "$IMAGE"; then
        RUNNER=podman
        return
    fi
    echo "podman run failed; running the image with buildah --isolation=chroot" >&2
    buildah from --name "$CONTAINER" "$IMAGE" >/dev/null
    buildah run --isolation=chroot --env SCHEDULER_PORT="$PORT" "$CONTAINER" -- python -m service &
    RUNNER=$!
}

in_container() {
    # Run a command in the started container.
    if [ "$RUNNER" = podman ]; then
        podman exec "$CONTAINER" "$@"
    else
        buildah run --isolation=chroot "$CONTAINER" -- "$@"
    fi
}

stop_container() {
    # Stop the service (SIGTERM, it drains) and remove the container.
    if [ "$RUNNER" = podman ]; then
        podman stop --time 10 "$CONTAINER" >/dev/null
        return
    fi
    # buildah run -> buildah-chroot-exec -> python: signal the service itself.
    kill -TERM "$(pgrep -P "$(pgrep -P "$RUNNER")")"
    wait "$RUNNER" || true
    buildah rm "$CONTAINER" >/dev/null
}

smoke_test() {
    # Start the image, wait for /readyz, post the tiny example, check the answer, stop it.
    local url=http://127.0.0.1:$PORT waited=0
    CONTAINER=scheduler-smoke-$$
    start_container
    trap stop_container RETURN
    until curl -sf "$url/readyz" >/dev/null; do
        if ((waited >= READY_TIMEOUT_S)); then
            echo "not ready within ${READY_TIMEOUT_S} s" >&2
            return 1
        fi
        sleep 2
        waited=$((waited + 2))
    done
    curl -sf -X POST "$url/v1/schedules" -H 'content-type: application/json' \
        --data @schemas/examples/tiny.json |
        python -c 'import json, sys; a = json.load(sys.stdin); assert a["checks"]["acyclic"] and a["checks"]["density"], a; print("smoke test passed:", a["solver"]["name"], a["cost"])'
    [ "$(in_container id -u)" != 0 ] || { echo "the container runs as root" >&2; return 1; }
    echo "runs as uid $(in_container id -u)"
}

podman image exists "$BASE" || build_base
build_wheels
podman build --isolation=chroot --format docker --build-arg BASE="$BASE" -t "$IMAGE" .
if [ "${SMOKE:-1}" = 1 ]; then smoke_test; fi
