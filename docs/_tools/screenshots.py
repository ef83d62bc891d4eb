#!/usr/bin/python3
"""Screenshots of the built documentation site with Debian's headless Chromium.

    screenshots.py build/release/docs/html docs/img

Loads the front page and the C++ API page of the integrators from the built site and writes
docs/img/site-front-page.png and docs/img/site-cpp-api.png (referenced by the contributing
page). Chromium runs with a fresh, empty profile and without network services.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

PAGES = {
    "site-front-page.png": "index.html",
    "site-cpp-api.png": "api/cpp-integrators.html",
}
WINDOW = "1280,1000"


def main() -> int:
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    html, out = Path(sys.argv[1]).resolve(), Path(sys.argv[2]).resolve()
    chromium = shutil.which("chromium")
    if chromium is None:
        sys.exit("screenshots: chromium not found (scripts/bootstrap --screenshots installs it)")
    for image, page in PAGES.items():
        source = html / page
        if not source.is_file():
            sys.exit(f"screenshots: {source} is missing: build the site first (scripts/docs)")
        with tempfile.TemporaryDirectory(prefix="moreau-chromium-") as profile:
            command = [chromium, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                       "--no-first-run", "--disable-background-networking",
                       "--disable-component-update", "--disable-sync",
                       f"--user-data-dir={profile}", "--hide-scrollbars",
                       f"--window-size={WINDOW}", f"--screenshot={out / image}",
                       source.as_uri()]
            result = subprocess.run(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                    text=True, timeout=120, check=False)
        if result.returncode != 0 or not (out / image).is_file():
            sys.exit(f"screenshots: chromium failed on {page}:\n{result.stdout}")
        print(f"screenshots: {out / image} ({page})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
