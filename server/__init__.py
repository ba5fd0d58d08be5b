"""FastAPI operator console backend."""
