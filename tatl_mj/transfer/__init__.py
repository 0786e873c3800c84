"""Transfer algorithms of the paper: FQI (Phase I), manifold alignment (Phase II),
the target apprentice (Algorithm 2), the TA-TL policy (Algorithm 1), the UMA-TL and
RL baselines (``methods``), and the interface a user's own method implements (``method``).

Pure numpy / scipy / scikit-learn: nothing here imports mujoco or a suite domain.
"""

from tatl_mj.transfer.alignment import AffineMapping, IdentityMapping, LinearAlignment, Mapping, align_manifolds
from tatl_mj.transfer.apprentice import Apprentice, fit_apprentice, learn_apprentice
from tatl_mj.transfer.features import RBF, Features, LinearFeatures, OneHot, make_features
from tatl_mj.transfer.fqi import ExtraTrees, LinearQ, LinearRegressor, QFunction, fitted_q_iteration, make_regressor
from tatl_mj.transfer.method import Policy, TransferMethod, TransferProblem
from tatl_mj.transfer.methods.target_fqi import RL, UMATL, MappedQ, TargetFQI
from tatl_mj.transfer.methods.tatl import TATL
from tatl_mj.transfer.registry import METHODS
from tatl_mj.transfer.tabular_q import TabularQ, q_iteration
from tatl_mj.transfer.tatl import DiscreteTATLPolicy, TATLPolicy, TATLStep

__all__ = [
    "AffineMapping",
    "Apprentice",
    "DiscreteTATLPolicy",
    "ExtraTrees",
    "Features",
    "IdentityMapping",
    "LinearAlignment",
    "LinearFeatures",
    "LinearQ",
    "LinearRegressor",
    "METHODS",
    "MappedQ",
    "Mapping",
    "OneHot",
    "Policy",
    "QFunction",
    "RBF",
    "RL",
    "TATL",
    "TATLPolicy",
    "TATLStep",
    "TabularQ",
    "TargetFQI",
    "TransferMethod",
    "TransferProblem",
    "UMATL",
    "align_manifolds",
    "fit_apprentice",
    "fitted_q_iteration",
    "learn_apprentice",
    "make_features",
    "make_regressor",
    "q_iteration",
]
