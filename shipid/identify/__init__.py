"""Identification: the augmented-state EKF identifier, its smoother, diagnostics and results."""
from .ekf import EKFOutput, EKFProblem, rts_smooth, run_ekf
from .identifier import EKFIdentifier, NotFittedError
from .recipe import RecipeFit, fit_logs
from .result import FitResult, load_result, model_from

__all__ = ["fit_logs", "RecipeFit", "EKFIdentifier", "NotFittedError", "FitResult", "load_result", "model_from", "EKFProblem", "EKFOutput", "run_ekf", "rts_smooth"]
