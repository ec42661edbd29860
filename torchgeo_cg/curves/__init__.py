"""torchgeo_cg.curves (being built)."""

__all__: list[str] = []
