"""Run execution: worker processes, the executor that feeds them, and the live hub."""
