"""The robust settings: every field has one kind (graph.params.ROBUST_KINDS), and the decision settings, the few
that define the model a loop is judged by, each carry a documented reason and a unit or a set of choices."""
import dataclasses
import enum
import typing

from graph.params import ROBUST_KINDS, RobustParams


def test_every_robust_setting_has_exactly_one_kind():
    names = [f.name for f in dataclasses.fields(RobustParams)]
    listed = [n for kind in ROBUST_KINDS.values() for n in kind]
    assert sorted(listed) == sorted(names)


def test_decision_settings_are_few_and_documented():
    hints = typing.get_type_hints(RobustParams)
    fields = {f.name: f for f in dataclasses.fields(RobustParams)}
    decision = ROBUST_KINDS["decision"]
    assert len(decision) <= 12
    for name in decision:
        f = fields[name]
        is_choice = isinstance(hints[name], type) and issubclass(hints[name], enum.Enum)
        assert is_choice or f.metadata.get("unit"), name
        assert is_choice and name == "method" or len(f.metadata.get("doc", "")) > 60, name
