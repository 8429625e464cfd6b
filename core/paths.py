"""Where lobeview keeps what it computes and where it finds the shared sample assets.

Every cached artefact (the demo scene and its lightmap, cube maps, prefiltered maps, the DFG
table) lives under one cache folder: ``--cache DIR`` on the command line, else
``$LOBEVIEW_CACHE``, else ``$XDG_CACHE_HOME/lobeview`` (``~/.cache/lobeview``). Part of the
ground floor: imports nothing of lobeview.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

#: the checkout's root (the folder holding app/, viewer/, ...): lobeview is installed in editable
#: mode from it, so bench/ results and the shared assets beside it are found from here.
REPO_ROOT = Path(__file__).resolve().parents[1]


def cache_dir(override: str | os.PathLike | None = None) -> Path:
    """The cache folder: ``override`` (``--cache``), ``$LOBEVIEW_CACHE`` or the XDG default."""
    if override:
        return Path(override)
    root = os.environ.get("LOBEVIEW_CACHE")
    if root:
        return Path(root)
    return Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "lobeview"


def shared_assets_dir() -> Path | None:
    """The sample assets (HDR captures, glTF models, measured metals): ``$LOBEVIEW_ASSETS``, or
    ``shared/assets`` beside the checkout; None where neither exists (a wheel install), and
    callers then fall back to built-in assets and say so."""
    root = os.environ.get("LOBEVIEW_ASSETS")
    candidates = [Path(root)] if root else [REPO_ROOT.parent / "shared" / "assets"]
    return next((path for path in candidates if path.is_dir()), None)


def bench_results_dir() -> Path:
    """Default output folder of the benchmarks (bench/results in the checkout)."""
    return REPO_ROOT / "bench" / "results"


def lobeview_program() -> list[str]:
    """How to run this lobeview from any folder: the ``lobeview`` entry point that is running, by
    its absolute path, else this interpreter with ``-m lobeview``. A printed ``lobeview shot``
    failed when pasted in a shell without the virtual environment (issue 41)."""
    script = Path(sys.argv[0]) if sys.argv and sys.argv[0] else None
    if script is not None and script.name == "lobeview" and script.is_file():
        return [str(script.absolute())]
    return [sys.executable, "-m", "lobeview"]
