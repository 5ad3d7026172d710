"""The public surface every group shares: repr, docstrings, and classmethods that bind to
subclasses.

References: the dataclass fields (whose names test_jaxlie_compat checks against jaxlie's),
``inspect.getdoc``, and the class of what a constructor returns.
"""

from __future__ import annotations

import dataclasses
import inspect

import jax
import jax.numpy as jnp
from conftest import is_se, over_groups, over_se_groups


@over_groups
def test_repr_names_the_field_and_rounds_the_values(G):
    """repr names the parameter field and rounds the values to 5 decimals; as in jaxlie, SE
    groups print the rotation and the translation apart (``wxyz=[…], xyz=[…]``: the field
    name split after the rotation's). It works on traced and abstract elements."""
    T = G.exp(jnp.full(G.tangent_dim, 1e-7, jnp.float64))
    field = dataclasses.fields(G)[0].name
    labels = [field]
    if is_se(G):
        rotation_field = dataclasses.fields(type(G.identity().rotation()))[0].name
        assert field.startswith(rotation_field + "_"), (field, rotation_field)
        labels = [rotation_field, field[len(rotation_field) + 1 :]]
    text = repr(T)
    assert text.startswith(f"{G.__name__}({labels[0]}=[1. 0.") and text.endswith("])")
    assert [part.split("=")[0] for part in text[len(G.__name__) + 1 : -1].split(", ")] == labels
    assert "e-0" not in text  # rounded to 5 decimals
    assert "Array(" not in text and "dtype" not in text
    traced = jax.jit(lambda T: (repr(T), T)[1])  # repr of a traced element does not fail
    traced(T)
    shaped = repr(jax.eval_shape(lambda: G.identity((2,))))  # holds a ShapeDtypeStruct
    assert shaped.startswith(f"{G.__name__}({field}=ShapeDtypeStruct(shape=(2, ")


@over_se_groups
def test_a_subclass_gets_classmethods_bound_to_it(G):
    """Classmethods are jitted with their class bound (for ``.lower``); a subclass binds
    them again, so the constructor that builds ``cls(...)`` builds the subclass (checked on
    ``from_rotation_and_translation``, the SE groups' constructor from parts)."""

    class Pose(G):  # type: ignore[misc,valid-type]
        pass

    jax.tree_util.register_pytree_node(
        Pose, lambda T: ((T.parameters(),), None), lambda _, c: Pose(*c)
    )
    R = G._rotation_type.identity()
    T = Pose.from_rotation_and_translation(R, jnp.zeros(G.space_dim))
    assert type(T) is Pose and type(G.from_rotation_and_translation(R, T.translation())) is G


@over_groups
def test_every_public_method_is_documented(G):
    """help(G.method) shows text: overrides without their own docstring show the base's."""
    undocumented = [
        name
        for name in dir(G)
        if not name.startswith("_")
        and callable(getattr(G, name))
        and not (inspect.getdoc(getattr(G, name)) or "").strip()
    ]
    assert undocumented == [], undocumented
