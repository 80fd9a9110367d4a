"""A run's Rerun recording as a person sees it: Rerun's web viewer in headless Chromium, saved as a PNG.

    python examples/06_view_recording_in_browser.py                      # simulates and runs a short loop first
    python examples/06_view_recording_in_browser.py RUN/recording.rrd --png view.png
    python examples/06_view_recording_in_browser.py --no-screenshot      # only the recording and its size

Needs Debian's chromium (`apt-get install chromium`) and websocket-client (`pip install -e ".[view]"`); without
them the script says what is missing and exits with 2. The same on the command line: `vslam run SEQ --out RUN`,
then `rerun RUN/recording.rrd` (a desktop viewer) or `rerun --web-viewer RUN/recording.rrd` (a browser).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from vslam.app.run import run_sequence
from vslam.recording_viewer import screenshot, viewer_available
from vslam.sim import SimConfig, simulate


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("recording", nargs="?", help="a recording.rrd (default: simulate and run a short loop)")
    p.add_argument("--out", default="recording_view", help="work folder for the default run (./recording_view)")
    p.add_argument("--png", help="screenshot file (default OUT/view.png)")
    p.add_argument("--wait", type=float, default=40.0, help="seconds before the first shot (the viewer's start-up)")
    p.add_argument("--no-screenshot", action="store_true", help="only make the recording and report its size")
    a = p.parse_args(argv)
    out = Path(a.out)
    # 1. The recording: a given one, or `vslam run` on a 4 m loop driven twice (320x240, 10 frames/s), with the
    #    recording defaults (image downscaled to half and JPEG-encoded, every 3rd frame).
    rrd = Path(a.recording) if a.recording else out / "run" / "recording.rrd"
    if not a.recording:
        simulate(SimConfig(width=320, height=240, focal=250.0, length=4.0, laps=2, turn_radius=0.6, fps=10.0,
                           seed=4), out / "sequence", overwrite=True)
        summary = run_sequence(out / "sequence", out / "run")
        frames = len(summary.result.timestamps)
        print(f"recording {rrd}: {rrd.stat().st_size / 1000:.0f} kB, {rrd.stat().st_size / frames / 1000:.1f} kB "
              f"per frame over {frames} frames; {len(summary.result.accepted_loops)} loops accepted")
    if a.no_screenshot:
        return 0

    # 2. The viewer: `rerun --web-viewer` serves the file, headless Chromium (software rendering) opens it; the
    #    shot is taken once two shots in a row agree, i.e. once the viewer has loaded the whole file.
    missing = viewer_available()
    if missing:
        print(f"cannot take the screenshot here: missing {missing}")
        return 2
    png = screenshot(rrd, a.png or out / "view.png", wait=a.wait)
    print(f"wrote {png}: the default layout (3D scene, camera image, time series) of {rrd}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
