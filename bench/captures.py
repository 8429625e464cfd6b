"""The HDR captures of ../shared/assets/env that the benchmarks light their spheres with
(bench/light.py's views, bench/mitsuba.py's --env), found by stem or given as paths."""

from __future__ import annotations

from pathlib import Path


def environment_files(views=None) -> list[Path]:
    """The HDR captures of ../shared/assets/env (all, or those named by stem or path)."""
    from lobeview.core.paths import shared_assets_dir

    root = shared_assets_dir()
    found = sorted(p for p in (root / "env").rglob("*") if p.suffix in (".exr", ".hdr")) if root else []
    if not views:
        if not found:
            raise SystemExit("bench: no HDR captures in ../shared/assets/env; name files with --views")
        return found
    chosen = []
    for view in views:
        path = Path(view)
        if not path.exists():
            matches = [p for p in found if p.stem == view]
            if not matches:
                raise SystemExit(f"bench: no environment {view!r} (stems: {', '.join(p.stem for p in found)})")
            path = matches[0]
        chosen.append(path)
    return chosen
