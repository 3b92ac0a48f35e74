#!/usr/bin/env python3
"""Render a study site in sumo-gui to a PNG (under Xvfb when there is no display).

python tools/screenshot_site.py --site xueqing --out docs/figures/xueqing_overview.png --zoom 60
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from pedsafe_sumo.network.sites import SITE_HELP, UnknownSiteError, resolve_site  # noqa: E402
from pedsafe_sumo.sumo_binaries import sumo_binary  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="screenshot_site", description=__doc__.splitlines()[0])
    parser.add_argument("--site", default="xueqing", help=SITE_HELP)
    parser.add_argument("--out", type=Path, required=True, help="PNG file to write")
    parser.add_argument("--zoom", type=float, default=60.0, help="sumo-gui zoom in percent (250: junction)")
    parser.add_argument("--size", default="1400,1000", help="window size WIDTH,HEIGHT in pixels")
    args = parser.parse_args(argv)
    try:
        site = resolve_site(args.site)
    except UnknownSiteError as exc:
        parser.exit(2, f"screenshot_site: error: {exc}\n")
    info = json.loads(site.file("site.json").read_text(encoding="utf-8"))
    x, y = info["main_junction_xy"]
    out = args.out.resolve()
    out.parent.mkdir(parents=True, exist_ok=True)
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
        proc = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=120)
    if proc.returncode != 0 or not out.exists():
        detail = (proc.stderr.strip().splitlines() or ["no output"])[-1]
        parser.exit(1, f"screenshot_site: error: sumo-gui did not write {out}: {detail}\n")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
