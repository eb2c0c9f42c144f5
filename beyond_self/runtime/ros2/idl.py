"""Cyclone DDS's Python types for ROS 2 messages, built from rosbags' definitions (the one
source of ROS types here): a DDS topic needs a type of the binding's, named as rmw names it
(`std_msgs::msg::dds_::String_`), with XTypes information. The samples themselves travel as
rosbags' CDR bytes, never through these classes."""

from __future__ import annotations

from functools import cache
from typing import Any

from cyclonedds.idl import IdlStruct, make_idl_struct
from cyclonedds.idl import types as t
from rosbags.interfaces import Nodetype

from beyond_self.runtime.ros2.convert import store
from beyond_self.schemas.ros2 import dds_type

# ROS 2 primitive -> IDL type, as rosidl maps a .msg into .idl (`char` is an 8-bit character)
BASE: dict[str, Any] = {
    "bool": bool, "byte": t.byte, "char": t.char, "int8": t.int8, "uint8": t.uint8,
    "int16": t.int16, "uint16": t.uint16, "int32": t.int32, "uint32": t.uint32,
    "int64": t.int64, "uint64": t.uint64, "float32": t.float32, "float64": t.float64,
}  # fmt: skip
# the binding's generic IDL types, indexed at run time (its stubs do not say they are generic)
ARRAY: Any = t.array
SEQUENCE: Any = t.sequence
BOUNDED_STR: Any = t.bounded_str


def _field(node: Any) -> Any:
    kind, detail = node
    if kind == Nodetype.NAME:
        return idl_type(detail)
    if kind == Nodetype.BASE:
        name, bound = detail
        if name == "string":
            return BOUNDED_STR[bound] if bound else str
        return BASE[name]
    inner, size = detail
    if kind == Nodetype.ARRAY:
        return ARRAY[_field(inner), size]
    return SEQUENCE[_field(inner), size] if size else SEQUENCE[_field(inner)]


@cache
def idl_type(ros_type: str) -> type[IdlStruct]:
    """The binding's struct for `ros_type` (`pkg/msg/Name`), fields in rosbags' order."""
    return topic_type(ros_type)


def topic_type(ros_type: str) -> type[IdlStruct]:
    """A struct for `ros_type` of its own (nested types shared): Cyclone shares one sertype
    between topics of the same Python class, and runtime.ros2.dds changes a topic's."""
    fields = {name: _field(node) for name, node in store().fielddefs[ros_type][1]}
    name = ros_type.rsplit("/", 1)[-1] + "_"
    return make_idl_struct(name, dds_type(ros_type), fields)
