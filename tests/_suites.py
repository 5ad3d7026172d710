"""The two suites: which checks are slow, and which fast check covers each one's code path.

``make test`` runs ``pytest -m "not slow"`` (the fast suite); ``make test-full`` runs every
test. A check is slow when a cheaper one already exercises its code path: the same kernel at
another dtype, spline degree, grid density or batch shape, or on a group that shares the
kernel; the docs build and the notebook runs are slow too (tests/README.md). ``SLOW`` is the
one list of them: each entry is a pattern of test ids (``re.fullmatch`` on the id after
``tests/``) and the fast check that covers the same code path. ``mark(items)`` is applied at
collection (``conftest.pytest_collection_modifyitems``) and fails the collection of the
whole suite when a pattern matches no test, or when a module is left with no fast test.
"""

from __future__ import annotations

import os
import re
from typing import Dict, List, Sequence, Tuple

import pytest

HEAVY = "SE3|Sim3|SE23"
"""The groups whose programs are largest (Sim(3)'s are ten times SE(3)'s, SE₂(3)'s two to
three times: docs/design/test-suite.md)."""

GENERIC_MODULES = (
    "transforms|batching|uncertainty|motion|from_matrix|validity|kernels|debug_nans|"
    "splines|edge_cases|jacobians|rank_promotion|manifold|euler_angles|alignment"
)
"""The modules whose checks exercise code shared by every group and dtype."""

GROUP_CHECKS = (
    "test_derivatives_of_log_exp_at_zero_and_pure_translation|"
    "test_no_nan_gradients_at_identity_and_pure_translation|test_jacobian_accuracy|"
    "test_ad_exact|test_left_right_relations|test_products_are_identity|"
    "test_jlog_is_jac_right_inv_of_log|test_ad_is_bracket_and_generates_adjoint|"
    "test_generator_action|test_reference_convention"
)
"""The checks of those modules that read each group's own kernels: they run on every group
and dtype in the fast suite too."""

_GROUP, _END = "(?<![A-Za-z0-9])(", ")(?![A-Za-z0-9])"

SLOW: List[Tuple[str, str]] = [
    # Second and third derivatives (float64 only): the fast suite checks values and first
    # derivatives of the same kernels, their series and their switches.
    (
        r"test_jacobians\.py::test_differentiable_at_zero\[.*\]",
        "test_jacobian_accuracy (every Jacobian against mpmath at 0 and tiny angles) and "
        "test_transforms::test_derivatives_of_log_exp_at_zero_and_pure_translation",
    ),
    (
        r"test_jacobians\.py::test_jlog_differentiable_at_identity\[.*\]",
        "test_axioms' jlog_matches_autodiff at the special tangents, zero included",
    ),
    (
        r"test_accuracy\.py::test_accuracy\[.*-hess-float64-.*\]",
        "test_accuracy's jac cells: the first derivative of log∘exp on the same grid",
    ),
    (
        r"test_transforms\.py::test_hessian_consistency\[.*\]",
        "test_transforms::test_jacfwd_jacrev_agree_with_finite_differences",
    ),
    (
        r"test_transforms\.py::test_hessian_of_log_exp_vanishes_at_zero_and_pure_translation"
        r"\[.*\]",
        "test_transforms::test_derivatives_of_log_exp_at_zero_and_pure_translation",
    ),
    (
        r"test_splines\.py::test_derivatives_equal_autodiff_of_the_curve\[.*\]",
        "test_splines::test_constant_body_velocity_is_reproduced (velocity, acceleration and "
        "jerk of every group against exact values) and test_continuity_across_every_knot",
    ),
    # Kernel sizes: float32 in the fast suite (the same kernels, the same series and
    # switches; float64 differs in term counts only).
    (
        r"test_kernel_sizes\.py::test_kernels_stay_within_their_recorded_size\[.*-float64\]",
        "the same test in float32",
    ),
    # Spline degrees: degree 3 on every group; degree 5, with every term of the
    # recursions, in the control-point Jacobians.
    (
        r"test_splines\.py::test_constant_body_velocity_is_reproduced\[.*-degree[1245]\]",
        "the same test at degree 3 on every group, and test_control_point_jacobians at 5",
    ),
    (
        r"test_splines\.py::test_fit_is_the_shared_least_squares_loop_with_every_linear_solver",
        "test_splines::test_fit_recovers_a_spline_from_its_samples and test_pose_graph's "
        "checks of each linear solver",
    ),
    # The group-generic modules (transformations, batching, uncertainty, motion,
    # from_matrix, validity, splines, ...) run on SO2, SE2 and SO3 in float64 in the fast
    # suite: their code is the same for every group and dtype. Every group's own kernels,
    # in both dtypes, are checked by the numeric tier, which stays fast whole: test_axioms
    # and test_geodesics on the regime batch, test_dtypes, test_accuracy against mpmath,
    # test_jacobians' accuracy and identities, and the first derivatives at the delicate
    # points in test_transforms.
    (
        rf"test_({GENERIC_MODULES})\.py::(?!{GROUP_CHECKS}\[).*\[.*{_GROUP}({HEAVY})"
        rf"{_END}.*\]",
        "the same test on SO2, SE2 and SO3, and the numeric tier on SE3, Sim3 and SE23",
    ),
    (
        rf"test_({GENERIC_MODULES})\.py::(?!{GROUP_CHECKS}\[).*\[.*float32.*\]",
        "the same test in float64 (one code path for both dtypes), and the numeric tier in "
        "float32 on every group",
    ),
    (
        rf"test_jacobians\.py::test_(left_right_relations|products_are_identity|"
        rf"jlog_is_jac_right_inv_of_log|ad_is_bracket_and_generates_adjoint|"
        rf"generator_action)\[({HEAVY})-float32\]",
        "the same test in float64, and test_jacobian_accuracy in float32",
    ),
    (
        r"test_rank_promotion\.py::test_rank_promotion_raise\[.*-U\]",
        "the same test with T of the higher rank (every function traced; the two-operand "
        "functions broadcast symmetrically)",
    ),
    (
        r"test_scalar\.py::test_sim3_(coefficients|family)_accuracy\[float32\]",
        "the same test in float64 (one code path for both dtypes), and test_accuracy's "
        "float32 cells of Sim3 exp, log and d log∘exp, which read these coefficients",
    ),
    (
        r"test_jaxlie_compat\.py::.*\[.*float32.*\]",
        "the same test in float64 (the comparisons read the same code in both dtypes)",
    ),
    (
        r"test_least_squares\.py::test_closed_form_jacobian_equals_autodiff\[SE3\]",
        "the same test on SE2 (the linearisation is one code path for every group), and "
        "test_pose_graph's SE2 solves, whose edges carry closed-form Jacobians",
    ),
    (
        r"test_pose_graph\.py::.*\[SE3\]",
        "the same test on SE2 (the solver is one code path for both dimensions), and "
        "test_example_pose_graph on SE3",
    ),
    (
        r"test_splines\.py::test_control_point_jacobians_equal_jacfwd\[SE2-.*\]",
        "the same test on SO2 and SO3 (the recursions are the same code on every group)",
    ),
    (
        r"test_uncertainty\.py::test_mean_derivatives_against_finite_differences\[SE2\]",
        "the same test on SO3 (one iteration for every group)",
    ),
    (
        r"test_typing\.py::test_usage_runs_with_the_types_it_asserts",
        "test_typing::test_mypy_accepts_the_package_and_infers_user_types (the same file, "
        "checked statically)",
    ),
    (
        r"test_debug_nans\.py::test_debug_nans_without_jit\[(SE2|SO3)\]",
        "the same test on SO2, and test_transforms::test_no_nan_gradients_at_identity_and_"
        "pure_translation on every group",
    ),
    # Subprocesses, the docs and the notebooks.
    (
        r"test_batching\.py::test_(chunked|elementwise)_ops_on_a_sharded_batch.*",
        "test_batching::test_in_chunks_equals_whole_batch (one device)",
    ),
    (
        r"test_pose_graph\.py::test_sharded_over_four_host_devices",
        "test_pose_graph's solves on one device",
    ),
    (
        r"test_pose_graph_landmarks\.py::test_landmark_files_reach_gtsam_optimum\[.*\]",
        "test_pose_graph_landmarks::test_solve_recovers_exact_landmarks (the same factors, "
        "on a small graph) and test_observation_jacobian_matches_autodiff",
    ),
    (
        r"test_docs\.py::test_(site_loads|maths_is|links_resolve|anchors_lead|group_pages|"
        r"site_builds|notebooks_are_pages|notebook_pages_keep|every_public|each_group_page|"
        r"python_blocks|search_works).*",
        "test_api_surface (the public names) and test_docs::test_readme_links_resolve",
    ),
    (
        r"test_notebooks\.py::test_0[0-9]_.*",
        "test_examples (the same operations in the examples' quick runs)",
    ),
    (
        r"test_bundle_adjustment\.py::test_(optimum_equals_gtsams|implicit_gradient_.*)",
        "test_bundle_adjustment's cost against GTSAM's and Schur steps against dense ones; "
        "test_least_squares' implicit derivative against central differences",
    ),
    (
        r"test_examples\.py::test_(batched_pose_fits|learn_odometry_scale)_quick",
        "test_least_squares::test_pose_graph_reaches_a_stationary_point_and_vmap_equals_each_"
        "alone and ::test_implicit_derivative_equals_central_differences",
    ),
]
"""``(pattern of test ids, the fast check that covers the same code path)``."""


def suite(config: pytest.Config) -> str | None:
    """``"fast"`` for a whole run of ``-m "not slow"``, ``"full"`` for a whole run of every
    test, ``None`` for any other selection (``-k``, ``--lf``, paths, another ``-m``)."""
    opt = config.option
    if getattr(opt, "keyword", "") or getattr(opt, "lf", False):
        return None
    if getattr(opt, "failedfirst", False) or getattr(opt, "deselect", None):
        return None
    root = config.rootpath
    default = {os.path.normpath(root / p) for p in config.getini("testpaths")} or {str(root)}
    given = {os.path.normpath(os.path.abspath(a)) for a in config.args}
    if given and given != default:  # paths or test ids chosen
        return None
    return {"": "full", "not slow": "fast"}.get(getattr(opt, "markexpr", "").strip())


def mark(items: Sequence[pytest.Item], whole: bool) -> None:
    """Mark the slow items; with ``whole`` (the default selection was collected), fail on a
    pattern that matched nothing or a module left without a fast test."""
    rules = [re.compile(p) for p, _ in SLOW]
    used: Dict[str, int] = {p.pattern: 0 for p in rules}
    fast_modules: Dict[str, int] = {}
    for item in items:
        nodeid = item.nodeid.removeprefix("tests/")
        module = nodeid.split("::")[0]
        fast_modules.setdefault(module, 0)
        slow = False
        for pattern in rules:
            if pattern.fullmatch(nodeid):
                used[pattern.pattern] += 1
                slow = True
        if slow:
            item.add_marker(pytest.mark.slow)
        elif "slow" not in item.keywords:
            fast_modules[module] += 1
    if not whole:
        return
    stale = [p for p, n in used.items() if n == 0]
    if stale:
        raise pytest.UsageError(f"tests/_suites.py: SLOW patterns that match no test: {stale}")
    bare = sorted(m for m, n in fast_modules.items() if n == 0)
    if bare:
        raise pytest.UsageError(f"tests/_suites.py: modules with no fast test: {bare}")
