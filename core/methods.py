"""The method vocabulary of lobeview: one grammar for the command line, the panel, the benchmark
tables, the scripts and every printed command.

    lobe-N[+norm]   the thesis' deterministic in-lobe pattern, N in [1, MAX_PATTERN]; ``+norm``:
                    lobeview's energy normalisation of Eq. 4.25 by the lobe's albedo table
    lobe-N+eq4.24   the same pattern with the thesis' derived quadrature Eq. 4.24 instead of
                    its empirical Eq. 4.25 (for the comparison of Fig. 4.24; not normalised)
    lobe-N...+ring  the thesis' ring at every N (by default isotropic lobes take a double
                    ring from N = 11 on, materials/patterns.py step 3); after +norm / +eq4.24
    fis-N           filtered importance sampling (Colbert & Krivanek 2007), N in [1, MAX_SAMPLES]
    mc-N            plain importance sampling, no filtering
    reference       converged MIS integration, REFERENCE_BATCH samples per lobe and pass
    prefiltered[-MODE]  one lookup per lobe into prefiltered maps, MODE in PREFILTER_MODES

``str(Method.parse(text)) == text`` for every canonical name, and ``Method.parse(str(m)) == m``
for every method (tests/test_core.py). Command lines add two flags, both on by default:
``--lobe-normalize``, so ``--method=lobe-11`` normalises unless ``--no-lobe-normalize`` is given,
and ``--lobe-fit``, so a bare lobe-N reads the fitted pattern (``+fit``) where N has a fitted
table unless ``--no-lobe-fit`` is given: ``--method=lobe-11`` is lobe-11+norm+fit, and a name with
a suffix (``lobe-11+norm``: the thesis pattern) is taken as written.
:func:`resolve_cli_method` and :func:`method_cli_flags` are the two directions of that rule.

This module is part of lobeview's ground floor (``lobeview.core``): it imports nothing of
lobeview, so the materials, scenes, renderer and app all read the same constants.
"""

from __future__ import annotations

import dataclasses
import math
import re
from dataclasses import dataclass

#: the kinds of methods, in the order the panel lists them
KINDS = ("lobe", "fis", "mc", "reference", "prefiltered")
#: the kinds the viewer renders while the camera moves (reference is what refinement converges to)
REALTIME_KINDS = ("lobe", "fis", "mc")
#: prefiltered sub-modes: auto = split-sum for microfacet/glTF lobes, lobe maps for the rest;
#: banks = Banks maps for anisotropic lobes, lobe maps for isotropic ones; rsibr = reflection-space
#: IBR (Cabral et al. 1999) for the microfacet reflection lobes, auto for the rest
PREFILTER_MODES = ("auto", "splitsum", "lobe", "lobe2d", "phong", "multi", "banks", "rsibr")
#: the shader lookups of the prefiltered modes' lobes (shaders/prefiltered.glsl LOBE_MAP_*, codes
#: by position; viewer/prefilter_modes.py says which lobe uses which)
PREFILTER_LOOKUPS = ("splitsum", "lobes", "banks")
MAX_LOBES = 8  # specular/transmission lobes per material (spec validation, GPU layout)
MAX_PATTERN = 32  # lobe-N samples per lobe (the pattern uniform array)
MAX_SAMPLES = 4096  # fis-N / mc-N samples per lobe and frame
REFERENCE_BATCH = 64  # samples per lobe per pass of the reference method
# ... and on a Rational BRDF: llvmpipe's loop limiter (65 535 loop iterations per invocation, all
# loops counted) cuts a 64-sample pass short, as every environment sample inverts both rational
# CDFs (measured: 2 % black pixels in a grid at 64 samples per pass, none at 4).
RATIONAL_REFERENCE_BATCH = 4
NORMALIZE_SUFFIX = "+norm"
#: lobe-N quadratures (thesis 4.4.3): Eq. 4.25 (lobeview's and the thesis' choice) and Eq. 4.24
WEIGHTINGS = ("eq4.25", "eq4.24")
EQ424_SUFFIX = "+eq4.24"
#: lobe-N pattern choices: auto = the thesis' ring below N = 11 and a double ring from 11 on
#: (materials/patterns.py DOUBLE_RING_MIN_SAMPLES), ring = the thesis' ring at every N, fitted =
#: reads fitted to the lobe (materials/fitted_pattern.py; isotropic microfacet lobes, +norm only,
#: the N with a committed table; other lobes keep auto). The command line's and the panel's
#: default for a normalised lobe-N (issue 45: 1.9-3.4 % against Mitsuba where auto is 3.1-9.0 %).
LOBE_PATTERNS = ("auto", "ring", "fitted")
RING_SUFFIX = "+ring"
FIT_SUFFIX = "+fit"
PATTERN_SUFFIXES = {"auto": "", "ring": RING_SUFFIX, "fitted": FIT_SUFFIX}
# A reference is the pixel's integral under a box filter: each pass shades at another sub-pixel
# position (viewer/camera.py pixel_offset), so a reference of spp samples takes at least
# min(spp, MIN_PIXEL_POSITIONS) passes (smaller batches) to resolve what a pixel covers.
PIXEL_FILTERS = ("box", "point")
MIN_PIXEL_POSITIONS = 64
# A reference reads the renderer's table of 65 536 Sobol points (viewer/shading.py) once:
# more samples per lobe would wrap around it and add the same points again.
MAX_REFERENCE_SPP = 65536

# MIP level bias b in lod = 0.5 log2(Omega_s / Omega_p) + b, chosen by `lobeview bench`'s sweep
# (mean PSNR over 6 material classes x 2 HDR environments at 640x400, b in -1..2; details in
# bench/results): fis-N is best at -0.5 (fis-16) to 0 (fis-64), not Colbert & Krivanek's +1
# (fis-16: 31.3 dB vs 25.6 dB); lobe-N at -1 (lobe-7) to -0.5 (lobe-15), not the thesis' 0
# (lobe-7: 30.8 dB vs 27.3 dB). The best bias grows with N for the ring pattern: its samples sit
# on one ring, so the filter that closes the gaps shrinks more slowly than the lobe area / N of
# Eq. 4.14. Those sweeps read box-filtered MIP chains (glGenerateMipmap); the chains are now
# tent-filtered (viewer/mip_chain.py), whose levels are blurrier: lobe-N reads them best at -1
# (bench/results/mip_chain-*.md: tent at -1 beats box at -0.5 on 11 of 14 sphere cells), fis-N
# stays at -0.5 (tent ahead of box there on 8 of 14).
DEFAULT_FIS_LOD_BIAS = -0.5
DEFAULT_LOBE_LOD_BIAS = -1.0
BOX_CHAIN_LOBE_LOD_BIAS = -0.5  # lobe-N's default on the box chain (--mip-filter box: as before the tent)

_GRAMMAR = re.compile(
    r"^(?:(?P<kind>lobe|fis|mc)-(?P<n>\d+)(?:(?P<norm>\+norm)|(?P<eq424>\+eq4\.24))?(?P<ring>\+ring)?(?P<fit>\+fit)?"
    r"|(?P<reference>reference)"
    r"|prefiltered(?:-(?P<mode>[a-z0-9]+))?)$"
)
GRAMMAR_HELP = (
    "lobe-N[+norm|+eq4.24][+ring], lobe-N+norm+fit, fis-N, mc-N, reference or prefiltered[-"
    + "|-".join(PREFILTER_MODES[1:])
    + "]"
)


class MethodError(ValueError):
    """A method name outside the grammar, or a sample count outside its limits."""


@dataclass(frozen=True)
class Method:
    kind: str  # one of KINDS
    samples: int  # N per lobe (reference: per pass; prefiltered: 1)
    normalize: bool = False  # lobe-N: energy normalisation by the lobe's albedo table
    mode: str = ""  # prefiltered: one of PREFILTER_MODES
    weighting: str = "eq4.25"  # lobe-N: the quadrature, one of WEIGHTINGS
    pattern: str = "auto"  # lobe-N: the isotropic lobes' pattern choice, one of LOBE_PATTERNS

    def __post_init__(self):
        if self.kind not in KINDS:
            raise MethodError(f"unknown method kind {self.kind!r}; use one of {', '.join(KINDS)}")
        if self.kind in ("lobe", "fis", "mc") and not 1 <= self.samples <= sample_limit(self.kind):
            raise MethodError(f"{self.kind}-{self.samples}: N must be in [1, {sample_limit(self.kind)}]")
        if self.kind == "reference" and self.samples < 1:
            raise MethodError(f"reference: samples per pass must be >= 1, got {self.samples}")
        if self.normalize and self.kind != "lobe":
            raise MethodError(f"energy normalisation ({NORMALIZE_SUFFIX}) applies to lobe-N only, not {self.kind}")
        if self.weighting not in WEIGHTINGS:
            raise MethodError(f"unknown lobe-N weighting {self.weighting!r}; use one of {', '.join(WEIGHTINGS)}")
        if self.weighting != "eq4.25" and self.kind != "lobe":
            raise MethodError(f"{EQ424_SUFFIX} (Eq. 4.24) applies to lobe-N only, not {self.kind}")
        if self.pattern not in LOBE_PATTERNS:
            raise MethodError(f"unknown lobe-N pattern {self.pattern!r}; use one of {', '.join(LOBE_PATTERNS)}")
        if self.pattern != "auto" and self.kind != "lobe":
            raise MethodError(f"{PATTERN_SUFFIXES[self.pattern]} (a pattern) applies to lobe-N only, not {self.kind}")
        if self.pattern == "fitted" and not self.normalize:
            raise MethodError(f"{FIT_SUFFIX} (fitted reads) is exact under uniform light through the albedo: "
                              f"write lobe-{self.samples}{NORMALIZE_SUFFIX}{FIT_SUFFIX}")  # fmt: skip
        if self.weighting == "eq4.24" and self.normalize:
            raise MethodError(f"{NORMALIZE_SUFFIX} normalises Eq. 4.25; {EQ424_SUFFIX} is Eq. 4.24 as printed")
        if self.kind == "prefiltered":
            if self.mode not in PREFILTER_MODES:
                raise MethodError(f"unknown prefiltered mode {self.mode!r}; use one of {', '.join(PREFILTER_MODES)}")
        elif self.mode:
            raise MethodError(f"only prefiltered methods have a mode, not {self.kind}")

    @classmethod
    def parse(cls, text: str) -> Method:
        m = _GRAMMAR.match(str(text).strip())
        if not m:
            raise MethodError(f"unknown method {text!r}; use {GRAMMAR_HELP}")
        if m.group("reference"):
            return cls("reference", REFERENCE_BATCH)
        if m.group("kind") is None:
            mode = m.group("mode") or "auto"
            if mode == "auto" and m.group("mode"):
                raise MethodError(f"{text!r}: write 'prefiltered' for the automatic mode")
            if mode not in PREFILTER_MODES:
                raise MethodError(f"unknown method {text!r}; use {GRAMMAR_HELP}")
            return cls("prefiltered", 1, mode=mode)
        kind = m.group("kind")
        norm, eq424, ring, fit = (bool(m.group(name)) for name in ("norm", "eq424", "ring", "fit"))
        if (norm or eq424 or ring or fit) and kind != "lobe":
            suffix = NORMALIZE_SUFFIX if norm else EQ424_SUFFIX if eq424 else RING_SUFFIX if ring else FIT_SUFFIX
            raise MethodError(f"{text!r}: {suffix} applies to lobe-N only")
        if ring and fit:
            raise MethodError(f"{text!r}: {RING_SUFFIX} and {FIT_SUFFIX} are two patterns; choose one")
        return cls(
            kind,
            int(m.group("n")),
            normalize=norm,
            weighting="eq4.24" if eq424 else "eq4.25",
            pattern="ring" if ring else "fitted" if fit else "auto",
        )

    def __str__(self) -> str:
        if self.kind == "reference":
            return "reference"
        if self.kind == "prefiltered":
            return "prefiltered" if self.mode == "auto" else f"prefiltered-{self.mode}"
        suffix = NORMALIZE_SUFFIX if self.normalize else EQ424_SUFFIX if self.weighting == "eq4.24" else ""
        suffix += PATTERN_SUFFIXES[self.pattern]
        return f"{self.kind}-{self.samples}" + suffix

    @property
    def family(self) -> str:
        """The benchmark's plot family: 'lobe', 'lobe+norm', 'lobe+eq4.24', each with '+ring' for
        the thesis' ring at every N, 'fis', 'mc', 'reference', 'prefiltered'."""
        ring = PATTERN_SUFFIXES[self.pattern]
        if self.weighting == "eq4.24":
            return "lobe" + EQ424_SUFFIX + ring
        return ("lobe+norm" if self.normalize else self.kind) + ring

    def with_samples(self, samples: int) -> Method:
        """The same method with another N (clamped to the kind's limit); prefiltered and
        reference keep theirs."""
        if self.kind not in ("lobe", "fis", "mc"):
            return self
        return dataclasses.replace(self, samples=int(min(max(samples, 1), sample_limit(self.kind))))

    def with_normalize(self, normalize: bool) -> Method:
        """lobe-N with or without energy normalisation; other methods, and Eq. 4.24 (which has
        none), unchanged."""
        if self.kind != "lobe" or self.weighting == "eq4.24":
            return self
        pattern = "auto" if self.pattern == "fitted" and not normalize else self.pattern  # +fit needs +norm
        return dataclasses.replace(self, normalize=bool(normalize), pattern=pattern)

    def default_lod_bias(self, mip_filter: str = "tent") -> float:
        """The measured best bias of this method on MIP chains made by ``mip_filter``
        (viewer/mip_chain.py: "tent", the default, or "box")."""
        if self.kind == "fis":
            return DEFAULT_FIS_LOD_BIAS
        return DEFAULT_LOBE_LOD_BIAS if mip_filter == "tent" else BOX_CHAIN_LOBE_LOD_BIAS

    def for_rational(self) -> Method:
        """This method with a reference pass small enough for a Rational BRDF's shader."""
        if self.kind == "reference" and self.samples > RATIONAL_REFERENCE_BATCH:
            return Method("reference", RATIONAL_REFERENCE_BATCH)
        return self

    def for_pixel_filter(self, spp: int, pixel_filter: str) -> Method:
        """The reference's pass size for ``spp`` samples under ``pixel_filter``: 'box' takes at
        least min(spp, MIN_PIXEL_POSITIONS) passes (one sub-pixel position each), 'point' keeps
        the batch (every pass at the pixel centre). Other methods are one pass, unchanged."""
        if pixel_filter not in PIXEL_FILTERS:
            raise MethodError(f"unknown pixel filter {pixel_filter!r}; use one of {', '.join(PIXEL_FILTERS)}")
        if self.kind == "reference" and not 1 <= spp <= MAX_REFERENCE_SPP:
            raise MethodError(
                f"reference: {spp} samples per lobe; use 1 to {MAX_REFERENCE_SPP} (the Sobol table's size: "
                "more would repeat its points)"
            )
        if self.kind != "reference" or pixel_filter == "point":
            return self
        return Method("reference", max(1, min(self.samples, spp // MIN_PIXEL_POSITIONS)))

    def passes(self, spp: int) -> int:
        """Passes that accumulate ``spp`` samples per lobe (reference); every other method is one pass."""
        return max(1, math.ceil(spp / self.samples)) if self.kind == "reference" else 1


def sample_limit(kind: str) -> int:
    return MAX_PATTERN if kind == "lobe" else MAX_SAMPLES


def realtime_choices() -> tuple[str, ...]:
    """The panel's method combo: the sampled kinds (N has its own slider) and every prefiltered mode."""
    return REALTIME_KINDS + tuple(str(Method("prefiltered", 1, mode=mode)) for mode in PREFILTER_MODES)


def method_choice(method: Method) -> str:
    """The panel's combo entry of a method."""
    return str(method) if method.kind == "prefiltered" else method.kind


def method_from_choice(choice: str, samples: int, normalize: bool, pattern: str = "auto") -> Method:
    """The method a combo entry + sample slider + normalisation checkbox (+ for lobe-N the
    thesis-ring or fitted-reads checkbox, ``pattern``) select; the fitted reads need the
    normalisation, without it lobe-N keeps its automatic pattern."""
    if choice.startswith("prefiltered"):
        return Method.parse(choice)
    method = Method(choice, 1).with_samples(samples).with_normalize(normalize)
    if method.kind != "lobe":
        return method
    if pattern == "fitted" and not method.normalize:
        pattern = "auto"
    return dataclasses.replace(method, pattern=pattern)


def resolve_cli_method(
    text: str, lobe_normalize: bool | None, lobe_fit: bool | None = None, fitted_counts: tuple[int, ...] = ()
) -> Method:
    """``--method`` with ``--lobe-normalize``/``--no-lobe-normalize`` and ``--lobe-fit``/
    ``--no-lobe-fit`` (None: a flag's default, on).

    A bare ``lobe-N`` takes both flags: normalised unless ``--no-lobe-normalize``, and then the
    fitted reads (``+fit``) where N has a fitted table (``fitted_counts``, from
    materials/fitted_pattern.py fitted_sample_counts) unless ``--no-lobe-fit``. A name with a
    suffix is taken as written: ``lobe-N+norm`` is the thesis pattern normalised, refused with an
    explicit ``--no-lobe-normalize``; ``lobe-N+norm+fit`` is refused with ``--no-lobe-fit`` or for
    an N without a table; ``lobe-N+eq4.24`` is Eq. 4.24 as printed whatever the flags (the
    normalisation is one of Eq. 4.25)."""
    method = Method.parse(text)
    if method.kind != "lobe" or method.weighting == "eq4.24":
        return method
    if method.pattern == "fitted":
        if lobe_fit is False:
            raise MethodError(f"--method {text} asks for the fitted reads that --no-lobe-fit turns off")
        if method.samples not in fitted_counts:
            counts = ", ".join(str(n) for n in fitted_counts) or "none"
            raise MethodError(f"--method {text}: lobe-N{NORMALIZE_SUFFIX}{FIT_SUFFIX} has fitted tables for "
                              f"N = {counts} only")  # fmt: skip
    if method.normalize:
        if lobe_normalize is False:
            raise MethodError(f"--method {text} asks for normalisation that --no-lobe-normalize turns off")
        return method
    return with_default_fit(method.with_normalize(lobe_normalize is not False), lobe_fit is not False, fitted_counts)


def with_default_fit(method: Method, lobe_fit: bool, fitted_counts: tuple[int, ...]) -> Method:
    """The default pattern rule of the command line and scripts: a normalised lobe-N with the
    automatic pattern reads the fitted pattern (``+fit``) when ``lobe_fit`` and N has a fitted
    table (``fitted_counts``). Every other method (``+ring``, unnormalised) is returned unchanged."""
    if method.kind != "lobe" or not method.normalize or method.pattern != "auto":
        return method
    if not lobe_fit or method.samples not in fitted_counts:
        return method
    return dataclasses.replace(method, pattern="fitted")


def method_cli_flags(method: Method) -> str:
    """The ``lobeview shot`` flags that select ``method`` (:func:`resolve_cli_method`'s inverse),
    written ``--flag=value`` so that pasting them always works."""
    if method.kind == "lobe" and not method.normalize and method.weighting == "eq4.25":
        return f"--method={method} --no-lobe-normalize"
    return f"--method={method}"
