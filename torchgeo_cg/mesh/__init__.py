"""torchgeo_cg.mesh (being built)."""

__all__: list[str] = []
