"""lobeview's benchmarks and test harnesses, one package (``lobeview.bench``), run as
``lobeview bench [matrix|stress|mirrors|report]``:

- ``matrix``: run time against error for every method (matrix.py orchestrates, targets.py holds
  what is rendered and how it is timed, metrics.py the error measures, report.py the Markdown
  and plots);
- ``stress``: the numerical stress grid and white-furnace harness (stress.py), which the test
  suite also uses;
- ``mirrors``: planar mirror passes (mirrors.py);
- ``report``: rewrite a run's Markdown and plots from its JSON.
The scripts beside them (preview_accuracy.py, prefiltered.py, convergence.py) run with
``python -m lobeview.bench.NAME``. Results go to bench/results, timestamped, never overwritten.
"""


class BenchError(ValueError):
    """A bad benchmark option or input: printed as ``lobeview: error: ...`` with exit status 2."""
