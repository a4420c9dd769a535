"""Terrain tilesets of a DEM (Cesium quantized-mesh, terrain-RGB), each tile simplified by a registered method.

* :mod:`terrainvis.tiles.scheme`: Cesium's geographic tiling scheme (EPSG:4326, TMS rows);
* :mod:`terrainvis.tiles.quantized_mesh`: the quantized-mesh-1.0 encoder and decoder;
* :mod:`terrainvis.tiles.tileset`: :func:`write_tileset` (``terrainvis tiles``), which needs
  pyproj (``pip install "terrainvis[tiles]"``);
* :mod:`terrainvis.tiles.keep_los`: each zoom's budget chosen by the line-of-sight verdicts
  its tiles keep (``--keep-los P``);
* :mod:`terrainvis.tiles.terrain_rgb`: Mapbox's terrain-RGB PNG tiles in Web Mercator
  (``--format terrain-rgb``, Pillow);
* :mod:`terrainvis.tiles.read`: :func:`open_tileset` and :func:`stitch_zoom`, a tileset
  (quantized-mesh-1.0 or terrain-RGB) read back as one TIN per zoom over a DEM
  (``terrainvis evaluate DEM TILESET_DIR --zoom Z``).
"""

from .quantized_mesh import DecodedTile, decode_tile, encode_tile, to_uv
from .read import Tiles, open_tileset, stitch_zoom
from .scheme import tile_bounds, tile_count, tile_ranges, tile_size, tiles_covering
from .tileset import DEFAULT_MAX_ERROR0, Tileset, ZoomReport, lonlat_rectangle, tile_lattice, write_tileset

__all__ = ["write_tileset", "Tileset", "ZoomReport", "lonlat_rectangle", "tile_lattice", "DEFAULT_MAX_ERROR0",
           "encode_tile", "decode_tile", "DecodedTile", "to_uv",
           "tile_bounds", "tile_count", "tile_size", "tiles_covering", "tile_ranges",
           "open_tileset", "stitch_zoom", "Tiles"]
