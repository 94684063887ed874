# One image for every zswarm process (router, world, agents, recorder).
FROM python:3.11-slim
WORKDIR /app
COPY pyproject.toml README.md ./
COPY agent agent
COPY world world
COPY zswarm zswarm
COPY topologies topologies
RUN pip install --no-cache-dir .
ENTRYPOINT []
