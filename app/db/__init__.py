"""Persistence: models, engine, repositories, migrations."""
