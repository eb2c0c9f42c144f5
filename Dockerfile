# One image for every process of a deployment: the router and each service (see
# docker-compose.yml and README "Deployment"). The command picks the role:
#   docker run --rm beyond-self router --zenoh-config /etc/beyond/zenoh/router.json5
#   docker run --rm --network host beyond-self service gestures
FROM python:3.11-slim

# espeak-ng: the speech service's synthesizer (without it, speech prints the sentences)
RUN apt-get update \
    && apt-get install -y --no-install-recommends espeak-ng \
    && rm -rf /var/lib/apt/lists/*

WORKDIR /opt/beyond-self
COPY pyproject.toml README.md ./
COPY beyond ./beyond
COPY cognition ./cognition
COPY runtime ./runtime
COPY schemas ./schemas
COPY services ./services
RUN pip install --no-cache-dir . \
    && python -c "import zenoh.ext, beyond.cli, services.registry"

# Deployment configs baked in as defaults; compose mounts ./deploy over them.
COPY deploy /etc/beyond

RUN useradd --create-home --uid 10001 beyond && mkdir -p /data/speech && chown -R beyond /data
USER beyond
WORKDIR /data
ENV PYTHONUNBUFFERED=1 \
    BEYOND_LOG_FORMAT=json
EXPOSE 7447
ENTRYPOINT ["beyond"]
CMD ["--help"]
