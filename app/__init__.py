"""mapwise application layer: command line, file I/O (and, later, the web service)."""
