# The diathermy simulation service (REST + WebSocket on port 8000, sessions under /data).
#
#   docker build -t diathermy .
#   docker run -p 8000:8000 -v diathermy-data:/data -e DIATHERMY_TOKENS=change-me diathermy
#
# CPU by default. For a CUDA image pick a base that has python3 and pip, and the matching
# torch wheel index; nothing else changes:
#   docker build -t diathermy:cuda \
#     --build-arg BASE_IMAGE=pytorch/pytorch:2.5.1-cuda12.4-cudnn9-runtime \
#     --build-arg TORCH_INDEX_URL=https://download.pytorch.org/whl/cu124 .
ARG BASE_IMAGE=python:3.11-slim

# The browser viewer's bundle (/viewer), built from viewer/package-lock.json.
FROM node:20-slim AS viewer
WORKDIR /src
COPY viewer ./viewer
RUN mkdir -p server/diathermy/service/static/viewer \
    && cd viewer && npm ci --no-audit --no-fund && npm run build

FROM ${BASE_IMAGE}
ARG TORCH_INDEX_URL=https://download.pytorch.org/whl/cpu

ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1

WORKDIR /app
COPY pyproject.toml README.md ./
COPY server ./server
COPY --from=viewer /src/server/diathermy/service/static/viewer/viewer.js ./server/diathermy/service/static/viewer/
RUN python3 -m pip install --extra-index-url "${TORCH_INDEX_URL}" . \
    && useradd --create-home --uid 1000 diathermy \
    && mkdir -p /data && chown diathermy /data

# Settings come from DIATHERMY_* variables (see docs/service.md); tokens at `docker run -e`.
ENV DIATHERMY_HOST=0.0.0.0 \
    DIATHERMY_PORT=8000 \
    DIATHERMY_DATA_DIR=/data
USER diathermy
VOLUME /data
EXPOSE 8000
HEALTHCHECK --interval=30s --timeout=3s \
    CMD python3 -c "import urllib.request; urllib.request.urlopen('http://127.0.0.1:8000/healthz')"
CMD ["diathermy", "serve"]
