"""The bundled terrains, installed as the package ``terrainvis.data`` (see README.md)."""
