# The GuideBot image: one image for the server, the building simulator and the robots.
#
#   docker build -t guidebot .                      (Python from python:3.11-slim, PyPI)
#   docker build --build-arg BASE=my/python311 --build-arg WHEELS=.cache/wheels \
#                --build-arg APT_PACKAGES= -t guidebot .       (offline: see README)
#
# BASE needs python3 (3.11+) with the venv module. WHEELS, a folder of the build context
# holding the guidebot wheel and its dependencies' wheels, installs without an index.
ARG BASE=python:3.11-slim
FROM ${BASE}
ARG APT_PACKAGES="espeak-ng"
ARG WHEELS=""
RUN if [ -n "$APT_PACKAGES" ]; then \
      apt-get update \
      && apt-get install -y --no-install-recommends $APT_PACKAGES \
      && rm -rf /var/lib/apt/lists/*; \
    fi
RUN python3 -m venv /opt/guidebot
ENV PATH=/opt/guidebot/bin:$PATH \
    PYTHONUNBUFFERED=1 \
    GUIDEBOT_WEB_DIR=/app/web
WORKDIR /app
COPY . /app
RUN if [ -n "$WHEELS" ]; then \
      pip install --no-index --find-links "/app/$WHEELS" guidebot; \
    else \
      pip install --no-cache-dir /app; \
    fi \
 && rm -rf /app/.cache
ENTRYPOINT ["guidebot"]
