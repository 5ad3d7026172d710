"""The names a release renamed stay one release as deprecated aliases: each call warns with
a ``DeprecationWarning`` that names the new name, and returns what the new name returns
(docs/migrating.md lists them)."""

from __future__ import annotations

import re
import warnings

import jax.numpy as jnp
import numpy as np
import pytest

from jaxlie_geo import SE3, SE23, SO3, Sim3

R = SO3.exp(jnp.array([0.3, -0.2, 0.5]))
T_VEC, V_VEC = jnp.array([1.0, 2.0, 3.0]), jnp.array([-0.5, 0.25, 4.0])
X = SE23.exp(jnp.arange(1.0, 10.0) / 10)

CASES = {
    "Sim3.from_rotation_translation_scale": (
        lambda: Sim3.from_rotation_translation_scale(R, T_VEC, 2.0),
        lambda: Sim3.from_rotation_translation_and_scale(R, T_VEC, 2.0),
        "Sim3.from_rotation_translation_and_scale",
    ),
    "SE23.from_rotation_position_velocity": (
        lambda: SE23.from_rotation_position_velocity(R, T_VEC, V_VEC),
        lambda: SE23.from_rotation_translation_and_velocity(R, T_VEC, V_VEC),
        "SE23.from_rotation_translation_and_velocity",
    ),
    "SE23.from_rotation_position_velocity(position=)": (
        lambda: SE23.from_rotation_position_velocity(R, position=T_VEC, velocity=V_VEC),
        lambda: SE23.from_rotation_translation_and_velocity(R, translation=T_VEC, velocity=V_VEC),
        "SE23.from_rotation_translation_and_velocity",
    ),
    "SE23.from_pose_velocity": (
        lambda: SE23.from_pose_velocity(SE3.from_rotation_and_translation(R, T_VEC), V_VEC),
        lambda: SE23.from_pose_and_velocity(SE3.from_rotation_and_translation(R, T_VEC), V_VEC),
        "SE23.from_pose_and_velocity",
    ),
    "SE23.position": (lambda: X.position(), lambda: X.translation(), "SE23.translation"),
}


def _values(x):
    return np.asarray(x.parameters() if hasattr(x, "parameters") else x)


@pytest.mark.parametrize("name", CASES)
def test_old_name_warns_and_gives_the_new_names_result(name):
    old, new, new_name = CASES[name]
    expected = _values(new())
    for _ in range(2):  # every call warns: the alias is not behind jit's cache
        with pytest.warns(DeprecationWarning, match=f"use {re.escape(new_name)}\\.$"):
            got = _values(old())
        np.testing.assert_array_equal(got, expected)


def test_the_new_names_do_not_warn():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for _, new, _ in CASES.values():
            new()
