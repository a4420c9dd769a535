"""Figure: a tileset `terrainvis tiles` wrote, drawn by CesiumJS in headless Chromium.

It writes the bundled DEM ``cumberland`` as a quantized-mesh tileset (``--method``, ``--zoom``),
serves it beside tests/browser/tileset.html and lets Cesium's Viewer draw it with software WebGL
(SwiftShader): no imagery, heights as colours with a contour every 50 m (the tiles carry no
normals, so Cesium cannot light them per slope), twice exaggerated, the camera looking north-north-east
from inside the tileset's rectangle (seen whole, with the globe around it, Cesium stops rendering:
docs/user-guide.md#terrain-tiles). It prints what Cesium drew and fails when Cesium reported an
error. It needs Debian's chromium (``apt-get install chromium``) and the cesium npm package
(``npm install --prefix tests/browser``). Command that made docs/figures/cesium_cumberland.png::

    python studies/cesium_screenshot.py -o docs/figures/cesium_cumberland.png
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))  # tests/browser/cesium_page.py: the server and the Chromium run the test uses

from terrainvis.io import bundled_terrain  # noqa: E402
from terrainvis.tiles import write_tileset  # noqa: E402
from tests.browser import cesium_page  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("-o", "--out", default="cesium_cumberland.png", help="the PNG to write")
    ap.add_argument("--method", default="greedy-insertion")
    ap.add_argument("--zoom", nargs=2, type=int, default=(8, 11), metavar=("MIN", "MAX"))
    ap.add_argument("--size", nargs=2, type=int, default=(1000, 640), metavar=("WIDTH", "HEIGHT"))
    ap.add_argument("--colors", type=int, default=128, help="colours of the PNG's palette (0: keep RGB)")
    ap.add_argument("--wireframe", action="store_true", help="draw the tiles' triangles instead of their surface")
    args = ap.parse_args(argv)
    reason = cesium_page.missing()
    if reason:
        print(f"cesium_screenshot: {reason}", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory(prefix="terrainvis-cesium-") as tmp:
        ts = write_tileset(bundled_terrain("cumberland"), Path(tmp) / "cumberland", method=args.method,
                           zooms=tuple(args.zoom))
        print(f"cumberland: {args.method} tiles, zooms 0 to {args.zoom[1]} (the method from zoom {args.zoom[0]}), "
              f"{sum(z.n_tiles for z in ts.zooms)} tiles")
        start = time.perf_counter()
        with cesium_page.serve(ts.out_dir) as base:
            got = cesium_page.run_page(cesium_page.page_url(base, view="inside", wireframe=args.wireframe),
                                       screenshot=args.out, size=tuple(args.size), timeout=300.0)
    seconds = time.perf_counter() - start
    rendered = got.get("rendered") or {}
    print(f"Cesium drew tiles of zooms {rendered.get('tiles_drawn')} in {seconds:.1f} s "
          f"(settled: {rendered.get('settled')}), tile errors {got['errors']}, render errors "
          f"{rendered.get('render_errors')}, exception {got['exception']}")
    if got["exception"] or got["errors"] or rendered.get("render_errors") or not rendered.get("settled"):
        return 1
    if args.colors:
        from PIL import Image

        with Image.open(args.out) as im:
            rgb = im.convert("RGB")
        rgb.quantize(colors=args.colors, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE).save(
            args.out, optimize=True)
    print(f"wrote {args.out} ({Path(args.out).stat().st_size / 1024:.0f} KB)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
