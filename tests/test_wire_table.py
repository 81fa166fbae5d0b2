"""The shared command-table layer (adapters/wire/table.py): variants, fixed values, tagged unions, and
handlers bound at import (a table entry naming a handler its adapter lacks fails loudly)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import pytest

from adapters.errors import LayoutError, UnknownCommandError
from adapters.osdk import adapter as osdk_adapter
from adapters.osdk import commands as osdk
from adapters.robomaster import adapter as rm_adapter
from adapters.robomaster import commands as rm
from adapters.rsdk import adapter as rsdk_adapter
from adapters.rsdk import commands as rsdk
from adapters.wire.layout import Field, Layout
from adapters.wire.table import CommandSpec, Table, TaggedUnion, bind_handlers

U8 = Layout([Field("a", "B")])


def _spec(name: str, cmd_id: int, variant: str | None = None, handler: str = "", **kw: Any) -> CommandSpec:
    return CommandSpec(name, 1, cmd_id, (U8,), variant=variant, handler=handler, **kw)


def test_variants_filter_lookups_and_name_the_variant_in_errors() -> None:
    table = Table([_spec("x", 1, "old"), _spec("x", 2, "new"), _spec("y", 3)], variants=("old", "new"))
    assert table.named("x", "new").cmd_id == 2 and table.named("y", "old").cmd_id == 3
    assert [s.cmd_id for s in table.at((1, 1), None)] == [1] and table.at((1, 1), "new") == ()
    with pytest.raises(UnknownCommandError, match="unknown command 'z'; valid: x, y"):
        table.named("z")
    plain = Table([_spec("y", 3)])  # no variants: every variant asked for finds its entries
    assert plain.named("y", "2024").cmd_id == 3 and plain.at((1, 3), "2024") == plain.at((1, 3))
    with pytest.raises(ValueError, match="'newer' is not one of"):
        Table([_spec("x", 1, "newer")], variants=("old", "new"))


def test_fixed_values_are_forced_and_checked() -> None:
    spec = _spec("x", 1, fixed={"a": 7}, defaults={"b": 1})
    assert spec.values({}) == {"a": 7, "b": 1} and spec.matches({"a": 7}) and not spec.matches({"a": 6})
    with pytest.raises(LayoutError, match="a is fixed at 7"):
        spec.values({"a": 6})


def test_tagged_union_with_and_without_head() -> None:
    arm = Layout([Field("v", "H")])
    headed = TaggedUnion("t", {1: arm}, head=Layout([Field("t", "B")]))
    assert headed.encode({"t": 1, "v": 0x0203}) == b"\x01\x03\x02" and headed.size == 3
    assert headed.decode(b"\x01\x03\x02") == {"t": 1, "v": 0x0203}
    whole = TaggedUnion("t", {1: (Layout([Field("t", "B"), Field("v", "H")]),)})
    assert whole.decode(b"\x01\x03\x02") == {"t": 1, "v": 0x0203}
    with pytest.raises(LayoutError, match="unknown t 2"):
        whole.decode(b"\x02\x00\x00")
    with pytest.raises(ValueError, match="not a head field"):
        TaggedUnion("t", {1: arm}, head=arm)


class _Adapter:
    def _on_a(self, f: Mapping[str, Any]) -> None: ...


def test_a_handler_named_in_the_table_must_exist() -> None:
    table = Table([_spec("a_push", 1, handler="_on_a"), _spec("b_push", 2)])
    assert bind_handlers(_Adapter, table) == {"a_push": _Adapter._on_a}
    renamed = Table([_spec("a_push", 1, handler="_on_a_renamed")])
    with pytest.raises(TypeError, match=r"a_push → _Adapter\._on_a_renamed"):
        bind_handlers(_Adapter, renamed)


def test_the_three_families_bind_their_pushes_through_the_table() -> None:
    assert set(osdk_adapter._PUSHES) == {s.name for s in osdk.COMMAND_TABLE.specs if s.handler}
    assert set(osdk_adapter._PUSHES) >= {
        "flight_data_push",
        "status_push",
        "event_push",
        "lost_authority_push",
    }
    assert set(rsdk_adapter._PUSHES) == {"param_push", "calibration_push"}
    assert {s.name for s in rsdk.COMMAND_TABLE.specs if s.handler} == set(rsdk_adapter._PUSHES)
    assert set(rm_adapter._PUSHES) == {s.name for s in rm.REFEREE_TABLE.specs if s.handler}
    assert "robot_status" in rm_adapter._PUSHES
