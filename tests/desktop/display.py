"""A virtual display for the desktop harness and the screenshots: Xvfb on the first free number
of :91-:95 (the numbers this project's desktop tools use), started and stopped here."""
from __future__ import annotations

import contextlib
import os
import shutil
import subprocess
import tempfile
import time

DISPLAYS = range(91, 96)


@contextlib.contextmanager
def virtual_display(size="1280x1024x24"):
    """Yield the environment (DISPLAY, QT_QPA_PLATFORM=xcb, ...) for a QGIS on a fresh Xvfb."""
    xvfb = shutil.which("Xvfb")
    if xvfb is None:
        raise RuntimeError("Xvfb is not installed (scripts/bootstrap installs it: apt-get install xvfb)")
    for number in DISPLAYS:
        if os.path.exists(f"/tmp/.X11-unix/X{number}") or os.path.exists(f"/tmp/.X{number}-lock"):
            continue
        proc = subprocess.Popen([xvfb, f":{number}", "-screen", "0", size, "-nolisten", "tcp"],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        for _ in range(50):
            if os.path.exists(f"/tmp/.X11-unix/X{number}") or proc.poll() is not None:
                break
            time.sleep(0.1)
        if proc.poll() is not None:
            continue  # taken meanwhile
        runtime = tempfile.mkdtemp(prefix="gs-xdg-")
        os.chmod(runtime, 0o700)
        env = dict(os.environ, DISPLAY=f":{number}", QT_QPA_PLATFORM="xcb", XDG_RUNTIME_DIR=runtime,
                   PROJ_DATA=os.environ.get("PROJ_DATA", "/usr/share/proj"))
        try:
            yield env
        finally:
            proc.terminate()
            proc.wait(10)
            shutil.rmtree(runtime, ignore_errors=True)
        return
    raise RuntimeError("no free display among :91-:95")
