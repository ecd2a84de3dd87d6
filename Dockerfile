# mapwise service image: the API, the dashboard and the run workers in one process tree.
FROM python:3.11-slim
ENV PYTHONDONTWRITEBYTECODE=1 PYTHONUNBUFFERED=1 NUMBA_CACHE_DIR=/tmp/numba-cache
WORKDIR /srv/mapwise
COPY pyproject.toml README.md ./
COPY estimation ./estimation
COPY app ./app
COPY frontend ./frontend
COPY migrations ./migrations
RUN pip install --no-cache-dir --upgrade pip "setuptools>=78.1.1" && pip install --no-cache-dir .
EXPOSE 8000
# Listening beyond loopback: every request needs a bearer token (`mapwise token create`).
CMD ["mapwise", "serve", "--host", "0.0.0.0", "--port", "8000"]
