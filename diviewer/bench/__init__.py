"""`diviewer bench`: headless frame timing per stage and the speed/accuracy table across methods (torch-free).

core (settings, the run), runner (GL and path-tracer timing, accuracy on the evaluation set), frontier
(equal-time, equal-error, smallest K, temporal stability), onnx_tools (untrained generators, FLOPs,
fp16/fp32/int8 variants), report (environment, table, JSON, plot).
"""

from diviewer.bench.core import QUICK, BenchSettings, quick, run_bench

__all__ = ["BenchSettings", "QUICK", "quick", "run_bench"]
