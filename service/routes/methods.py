"""``/v1/methods``: the registered allocation methods and their options."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Path

import alloc

from ..schemas import PROBLEM_RESPONSES, MethodOut

router = APIRouter(prefix="/v1/methods", tags=["methods"], responses=PROBLEM_RESPONSES)


@router.get("", response_model=list[MethodOut], summary="List allocation methods")
async def list_methods() -> list[MethodOut]:
    return [MethodOut(**alloc.method_info(name)) for name in alloc.methods()]


@router.get("/{name}", response_model=MethodOut, summary="One allocation method")
async def get_method(name: Annotated[str, Path(max_length=64)]) -> MethodOut:
    return MethodOut(**alloc.method_info(name))
