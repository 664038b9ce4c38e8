"""``/v1/ams``: attainable-moment-set summary of an inline problem."""

from __future__ import annotations

from fastapi import APIRouter, Request

from ..bodies import JsonRoute
from ..deps import PoolDep, end_parse_turn
from ..schemas import PROBLEM_RESPONSES, AmsOut, AmsRequest

router = APIRouter(prefix="/v1/ams", tags=["ams"], responses=PROBLEM_RESPONSES, route_class=JsonRoute)


@router.post("", response_model=AmsOut, summary="AMS volume and largest moments along directions")
async def ams_summary(body: AmsRequest, pool: PoolDep, request: Request) -> AmsOut:
    end_parse_turn(request)
    # in the build process: a facet enumeration is a build (time and memory bounded there)
    return await pool.ams_summary(body)
