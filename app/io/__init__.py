"""Log and map file formats."""
