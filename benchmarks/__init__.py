"""torchgeo_cg benchmarks: one ``bench_<area>.py`` per area, run by ``benchmarks/run.py``."""
