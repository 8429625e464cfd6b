"""Fitting from the viewer: one ``lobeview fit`` run in a background thread, with its progress
lines, cancellation and the parameters locked at the selected material's values.

The job runs app/fit.py's :func:`fit_description` (the command's own code and defaults) on a
worker thread: the fit is numpy only, no GL, so the window keeps drawing. The window polls
:meth:`FitJob.poll` once per frame and applies the finished material through the material editor
(undoable, like any edit). Cancelling raises :class:`FitCancelled` from the next progress line,
so a cancelled fit stops within one brute-force iteration.
"""

from __future__ import annotations

import argparse
import math
import threading
import time

FIT_MODELS = ("thesis", "microfacet", "rational")
# How many progress lines the panel keeps (the last is shown, all go to the log).
KEPT_LINES = 200


class FitCancelled(Exception):
    """Raised inside the worker when the user cancelled."""


def lockable_parameters(desc: dict, model: str) -> dict[str, float]:
    """The parameters of the selected material that the fit of ``model`` can hold fixed, as
    ``--fix`` names and values: a thesis material's kd and lobe parameters for a thesis fit
    (scalars only: an RGB kd or ks is not a single value to lock), a glTF material's roughness,
    metallic, signed anisotropy and transmission for a microfacet fit. Nothing otherwise."""
    out: dict[str, float] = {}
    if model == "thesis" and desc.get("model") == "thesis":
        if not isinstance(desc.get("kd"), list):
            out["kd"] = float(desc["kd"])
        for group, prefix, k_name in (("lobes", "lobe", "ks"), ("transmission_lobes", "tlobe", "kt")):
            for i, lobe in enumerate(desc.get(group, [])):
                for name in ("mx", "my", "r0", "alpha", k_name):
                    if not isinstance(lobe.get(name), list):
                        out[f"{prefix}{i + 1}.{name}"] = float(lobe[name])
    elif model == "microfacet" and desc.get("model") == "gltf":
        out["roughness"] = max(float(desc.get("roughness", 1.0)), 0.01)
        out["metallic"] = float(desc.get("metallic", 1.0))
        strength = float(desc.get("anisotropy", 0.0))
        rotation = float(desc.get("anisotropy_rotation", 0.0)) % math.pi
        # the fit's signed strength: along the tangent (rotation 0) or the bitangent (90 deg)
        if strength == 0.0 or min(rotation, math.pi - rotation) < 1e-6:
            out["anisotropy"] = strength
        elif abs(rotation - math.pi / 2) < 1e-6:
            out["anisotropy"] = -strength
        out["transmission"] = float(desc.get("transmission", 0.0))
    return out


class FitJob:
    """One fit on a worker thread. ``state``: running, done, failed or cancelled; ``result``:
    the material description once done; ``error``: the message once failed."""

    def __init__(self, data: str, model: str = "thesis", locked: dict | None = None, extra: list | None = None):
        if model not in FIT_MODELS:
            raise ValueError(f"model must be one of {', '.join(FIT_MODELS)}, got {model!r}")
        from lobeview.app.fit import add_fit_arguments

        parser = argparse.ArgumentParser(prog="lobeview fit", exit_on_error=False)
        add_fit_arguments(parser)
        argv = [data, "--model", model, *(extra or [])]
        for name, value in (locked or {}).items():
            argv += ["--fix", f"{name}={value!r}"]
        try:
            self.args = parser.parse_args(argv)
        except (argparse.ArgumentError, SystemExit) as exc:
            raise ValueError(f"fit options: {exc}") from None
        self.data, self.model = data, model
        self.locked = dict(locked or {})
        self.state = "running"
        self.lines: list[str] = []
        self.result: dict | None = None
        self.error = ""
        self.seconds = 0.0
        self._cancel = threading.Event()
        self._thread = threading.Thread(target=self._run, name="lobeview-fit", daemon=True)

    def start(self) -> FitJob:
        self._thread.start()
        return self

    def _progress(self, line: str) -> None:
        if self._cancel.is_set():
            raise FitCancelled
        self.lines.append(str(line))
        del self.lines[:-KEPT_LINES]

    def _run(self) -> None:
        from lobeview.app.fit import fit_description

        t0 = time.perf_counter()
        try:
            desc, _, _ = fit_description(self.args, self._progress)
            self.result = desc
            self.state = "done"
        except FitCancelled:
            self.state = "cancelled"
        except Exception as exc:  # noqa: BLE001 - any failure is shown in the panel, never crashes the viewer
            self.error = f"{type(exc).__name__}: {exc}" if not isinstance(exc, ValueError) else str(exc)
            self.state = "failed"
        self.seconds = time.perf_counter() - t0

    def cancel(self) -> None:
        self._cancel.set()

    def wait(self, timeout: float | None = None) -> str:
        self._thread.join(timeout)
        return self.state

    @property
    def running(self) -> bool:
        return self.state == "running"

    @property
    def status(self) -> str:
        """One line for the panel."""
        if self.state == "running":
            return self.lines[-1].strip() if self.lines else f"fitting {self.data} ..."
        if self.state == "done":
            return f"fitted in {self.seconds:.1f} s: Eq. 3.7 error {self.result['fit']['error']:.4g}"
        if self.state == "failed":
            return f"fit failed: {self.error}"
        return "fit cancelled"
