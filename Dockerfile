# One image for every process of a deployment: the router and each service (see
# docker-compose.yml and README "Deployment"). The command picks the role:
#   docker run --rm beyond-self router --zenoh-config /etc/beyond/zenoh/router.json5
#   docker run --rm --network host beyond-self service gestures
# BASE: any Debian-based Python 3.11 image with `python` and `pip` on PATH. Without a registry,
# deploy/base-image.sh builds one from Debian packages (--build-arg
# BASE=localhost/beyond-self-base:bookworm). Podman keeps the HEALTHCHECK only with
# `--format docker` (or BUILDAH_FORMAT=docker).
ARG BASE=python:3.11-slim
FROM ${BASE}

# The image's settings come first: with podman's vfs storage (deploy/podman/storage-vfs.conf)
# every step after a big layer copies that layer again, even when cached.
ENV PYTHONUNBUFFERED=1 \
    BEYOND_LOG_FORMAT=json
EXPOSE 7447
# Healthy while the container's service answers a health query on the bus, or its router
# accepts a session: `beyond health` finds which from the container's own processes.
HEALTHCHECK --interval=30s --timeout=15s --start-period=120s --retries=3 \
    CMD ["beyond", "health", "--timeout", "10"]
ENTRYPOINT ["beyond"]
CMD ["--help"]

# espeak-ng: the speech service's synthesizer (without it, speech prints the sentences); the
# local base has it already
RUN if ! command -v espeak-ng >/dev/null; then \
        apt-get update \
        && apt-get install -y --no-install-recommends espeak-ng \
        && rm -rf /var/lib/apt/lists/*; \
    fi \
    && useradd --create-home --uid 10001 beyond \
    && mkdir -p /data/speech && chown -R beyond /data

# Dependencies first, from pyproject.toml alone (and the build backend, so that installing the
# project itself needs no network): a change to the code reuses this layer. The packages' own
# test suites are left out (a quarter of the files).
# CA_BUNDLE: a CA file for pip behind a TLS-inspecting proxy, mounted into the build, e.g.
#   podman build -v /etc/ssl/certs/ca-certificates.crt:/run/ca.crt:ro --build-arg CA_BUNDLE=/run/ca.crt
ARG CA_BUNDLE=
WORKDIR /opt/beyond-self
COPY pyproject.toml ./
RUN if [ -n "$CA_BUNDLE" ]; then export PIP_CERT="$CA_BUNDLE"; fi \
    && python -c "import tomllib; print('\n'.join(tomllib.load(open('pyproject.toml', 'rb'))['project']['dependencies']))" > /tmp/requirements.txt \
    && python -m pip install --no-cache-dir -r /tmp/requirements.txt "setuptools>=77" wheel \
    && rm /tmp/requirements.txt \
    && find "$(python -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')" \
        -mindepth 2 -type d -name tests -prune -exec rm -rf {} +

# The project (.dockerignore lets only its packages, README and deploy configs in); the
# configs are also baked in as /etc/beyond, the defaults that compose mounts ./deploy over.
COPY . ./
COPY beyond_self/deploy /etc/beyond
RUN python -m pip install --no-cache-dir --no-deps --no-build-isolation . \
    && python -c "import zenoh.ext, beyond_self.cli, beyond_self.services.registry" \
    && rm -rf build *.egg-info

USER beyond
WORKDIR /data
