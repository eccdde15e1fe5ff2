"""jaxgfx.optim: fitting parameters by gradient descent or least squares, image losses and
bijections for bounded parameters (see docs/inverse.md).

This package never imports :mod:`jaxgfx.render`; losses that render are written by the caller
(or by :mod:`jaxgfx.pipelines.fit`) and passed to :func:`fit`.
"""

from ._estimators import decorrelated as decorrelated
from ._estimators import decorrelated_loss as decorrelated_loss
from ._estimators import decorrelated_residuals as decorrelated_residuals
from ._loop import FAST_COMPILE_OPTIONS as FAST_COMPILE_OPTIONS
from ._loop import LEAST_SQUARES_SOLVERS as LEAST_SQUARES_SOLVERS
from ._loop import OPTIMIZERS as OPTIMIZERS
from ._loop import CompiledStep as CompiledStep
from ._loop import FitResult as FitResult
from ._loop import LeastSquaresSolution as LeastSquaresSolution
from ._loop import compile_step as compile_step
from ._loop import fit as fit
from ._loop import fit_least_squares as fit_least_squares
from ._loop import least_squares_solve as least_squares_solve
from ._losses import LOSS_SPACES as LOSS_SPACES
from ._losses import LOSSES as LOSSES
from ._losses import censored_l2_loss as censored_l2_loss
from ._losses import image_loss as image_loss
from ._losses import l1_loss as l1_loss
from ._losses import l2_loss as l2_loss
from ._losses import relative_l2_loss as relative_l2_loss
from ._transforms import Interval as Interval
from ._transforms import from_unconstrained as from_unconstrained
from ._transforms import to_unconstrained as to_unconstrained

__all__ = [
    "fit",
    "fit_least_squares",
    "compile_step",
    "CompiledStep",
    "decorrelated",
    "decorrelated_loss",
    "decorrelated_residuals",
    "FitResult",
    "OPTIMIZERS",
    "FAST_COMPILE_OPTIONS",
    "least_squares_solve",
    "LeastSquaresSolution",
    "LEAST_SQUARES_SOLVERS",
    "l2_loss",
    "relative_l2_loss",
    "l1_loss",
    "image_loss",
    "censored_l2_loss",
    "LOSSES",
    "LOSS_SPACES",
    "Interval",
    "to_unconstrained",
    "from_unconstrained",
]
