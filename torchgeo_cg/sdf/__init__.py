"""torchgeo_cg.sdf (being built)."""

__all__: list[str] = []
