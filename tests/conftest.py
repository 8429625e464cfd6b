"""Test-wide settings: caches (demo scene, cube maps) go to a temporary folder, never to the
user's ~/.cache, and the demo scene is built at draft quality so CI stays fast."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

os.environ.setdefault("LOBEVIEW_CACHE", tempfile.mkdtemp(prefix="lobeview-test-cache-"))
os.environ.setdefault("LOBEVIEW_DEMO_QUALITY", "draft")

SHARED_ASSETS = Path(__file__).resolve().parents[1].parent / "shared" / "assets"
