"""Use cases: what the API and the CLI do, in terms of repositories and the numerical core."""
