#!/usr/bin/env python3
"""Render a study site in sumo-gui to a PNG (under Xvfb when there is no display).

python tools/screenshot_site.py --site xueqing --out docs/figures/xueqing_overview.png --zoom 60
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import struct
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from pedsafe_sumo.network.sites import SITE_HELP, UnknownSiteError, resolve_site  # noqa: E402
from pedsafe_sumo.network.sumo_inputs import config_inputs  # noqa: E402
from pedsafe_sumo.sumo_binaries import sumo_binary  # noqa: E402

#: Attempts at a snapshot of the asked size. Under load, sumo-gui can take its snapshot before the
#: window has its size and write an image a few pixels wide (seen once in CI); a new attempt
#: renders it again rather than shipping or testing a blank picture.
SNAPSHOT_ATTEMPTS = 3


def png_size_px(path: Path) -> tuple[int, int] | None:
    """(width, height) from a PNG's header, or None when the file is not a PNG."""
    try:
        header = path.read_bytes()[:24]
    except OSError:
        return None
    if len(header) < 24 or header[:8] != b"\x89PNG\r\n\x1a\n" or header[12:16] != b"IHDR":
        return None
    width, height = struct.unpack(">II", header[16:24])
    return int(width), int(height)


def window_size(text: str) -> str:
    """WIDTH,HEIGHT in pixels, each 100 or more (argparse type)."""
    try:
        width_px, height_px = (int(value) for value in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"give WIDTH,HEIGHT in pixels, got {text!r}") from None
    if min(width_px, height_px) < 100:
        raise argparse.ArgumentTypeError(f"a window of at least 100x100 pixels, got {text!r}")
    return f"{width_px},{height_px}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="screenshot_site", description=__doc__.splitlines()[0])
    parser.add_argument("--site", default="xueqing", help=SITE_HELP)
    parser.add_argument("--out", type=Path, required=True, help="PNG file to write")
    parser.add_argument("--zoom", type=float, default=60.0, help="sumo-gui zoom in percent (250: junction)")
    parser.add_argument(
        "--size", type=window_size, default="1400,1000", help="window size WIDTH,HEIGHT in pixels"
    )
    args = parser.parse_args(argv)
    try:
        site = resolve_site(args.site)
        config_inputs(site.file("sumocfg"))  # sumo-gui -c reads it: no output it names (docs/trust.md)
    except UnknownSiteError as exc:
        parser.exit(2, f"screenshot_site: error: {exc}\n")
    info = json.loads(site.file("site.json").read_text(encoding="utf-8"))
    x, y = info["main_junction_xy"]
    out = args.out.resolve()
    out.parent.mkdir(parents=True, exist_ok=True)
    width_px, height_px = (int(value) for value in args.size.split(","))
    detail = "no output"
    for attempt in range(1, SNAPSHOT_ATTEMPTS + 1):
        out.unlink(missing_ok=True)
        proc = _render(site, out, args, x, y, parser)
        size = png_size_px(out) if out.exists() else None
        # The window's decorations and a small screen may trim it; half the asked size is a real view.
        big_enough = size is not None and size[0] >= width_px // 2 and size[1] >= height_px // 2
        if proc.returncode == 0 and big_enough:
            break
        detail = (proc.stderr.strip().splitlines() or ["no output"])[-1]
        if size is not None:
            detail = f"the snapshot is {size[0]}x{size[1]} px, not about {width_px}x{height_px}"
        if attempt == SNAPSHOT_ATTEMPTS:
            out.unlink(missing_ok=True)
            parser.exit(1, f"screenshot_site: error: sumo-gui did not write {out} ({detail})\n")
        print(f"screenshot_site: attempt {attempt}: {detail}; rendering again", file=sys.stderr)
    print(f"wrote {out}")
    return 0


def _render(
    site, out: Path, args: argparse.Namespace, x: float, y: float, parser
) -> subprocess.CompletedProcess:
    with tempfile.TemporaryDirectory() as tmp:
        view = Path(tmp) / "view.xml"
        view.write_text(
            f'<viewsettings><scheme name="real world"/><viewport zoom="{args.zoom}" x="{x}" y="{y}"/>'
            f'<snapshot file="{out}" time="0"/></viewsettings>\n'
        )
        cmd = [
            sumo_binary("sumo-gui"),
            "-c",
            str(site.file("sumocfg")),
            "-g",
            str(view),
            "--start",
            "--quit-on-end",
            "-e",
            "1",
            "--window-size",
            args.size,
        ]
        if not os.environ.get("DISPLAY"):
            if not shutil.which("xvfb-run"):
                parser.exit(2, "screenshot_site: error: no display and no xvfb-run (apt-get install xvfb)\n")
            width, height = args.size.split(",")
            cmd = ["xvfb-run", "-a", "-s", f"-screen 0 {int(width) + 200}x{int(height) + 200}x24", *cmd]
        env = {**os.environ, "LIBGL_ALWAYS_SOFTWARE": "1"}
        return subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=120)


if __name__ == "__main__":
    raise SystemExit(main())
