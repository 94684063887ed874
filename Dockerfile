# One image for every zswarm process (router, recorder, world, agents).
#   docker build -t zswarm:latest .                         (python:3.11-slim, packages from PyPI)
#   docker build --build-arg BASE=IMAGE -t zswarm:latest .  (any base with python3 -m venv)
# A folder wheelhouse/ in the build context (pip wheel . -w wheelhouse) is installed
# offline instead, for machines that reach no registry (the compose test does this).
ARG BASE=python:3.11-slim
FROM ${BASE}
COPY . /src
RUN python3 -m venv /opt/zswarm \
    && if [ -d /src/wheelhouse ]; then \
         /opt/zswarm/bin/pip install --no-cache-dir --no-index --find-links /src/wheelhouse zswarm; \
       else \
         /opt/zswarm/bin/pip install --no-cache-dir /src; \
       fi \
    && rm -rf /src
ENV PATH=/opt/zswarm/bin:$PATH PYTHONUNBUFFERED=1
WORKDIR /app
ENTRYPOINT []
