"""``/v1/ams``: attainable-moment-set summary of an inline problem."""

from __future__ import annotations

from fastapi import APIRouter, Request

from .. import ams
from ..bodies import JsonRoute
from ..deps import StoreDep, end_parse_turn
from ..schemas import PROBLEM_RESPONSES, AmsOut, AmsRequest

router = APIRouter(prefix="/v1/ams", tags=["ams"], responses=PROBLEM_RESPONSES, route_class=JsonRoute)


@router.post("", response_model=AmsOut, summary="AMS volume and largest moments along directions")
async def ams_summary(body: AmsRequest, store: StoreDep, request: Request) -> AmsOut:
    end_parse_turn(request)
    # in the build process: a facet enumeration is a build (time and memory bounded there)
    problem = body.to_problem()
    return await store.run_bounded(ams.summarize, problem, body.directions, store.build_budget)
