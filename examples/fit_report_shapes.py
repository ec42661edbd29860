"""Recover the report's Table 3 automatically: shapes A–H fitted in one batched call.

Run: python examples/fit_report_shapes.py  (writes fit_report_shapes.png)
"""

import torch

from torchgeo_cg.transforms import SolverOptions, fit_report_shapes, fit_transform, report_shapes
from torchgeo_cg.transforms.report_shapes import format_report_table

OUTPUT = globals().get("OUTPUT", "fit_report_shapes.png")

# The data: our start shape (a letter F; the report does not give its own) and the
# eight targets of Table 3, built with translation/rotation/scale_x/scale_y/shear/homography.
shapes = report_shapes(dtype=torch.float64)
src = shapes.start.expand(8, -1, -1)  # (8, 10, 2): one problem per letter

# One batched call fits all eight: a homography each, Levenberg-Marquardt from the identity.
fit = fit_transform(src, shapes.targets, model="homography", solver=SolverOptions("lm"))
print(f"{fit.history.shape[0] - 1} LM iterations, final loss {fit.loss.max():.1e}")

# The Table-3-style summary: truth next to the recovered transform in report terms.
summary = fit_report_shapes()  # homography and affine fits, with errors
print(format_report_table(summary))

try:
    from torchgeo_cg.viz.estimation import plot_report_fits
except ImportError:  # matplotlib is an optional extra
    print("install matplotlib for the figure")
else:
    plot_report_fits(summary, OUTPUT)
    print(f"wrote {OUTPUT}")
