"""``/v1/ams``: attainable-moment-set summary of an inline problem."""

from __future__ import annotations

from fastapi import APIRouter

from .. import ams
from ..schemas import PROBLEM_RESPONSES, AmsOut, AmsRequest

router = APIRouter(prefix="/v1/ams", tags=["ams"], responses=PROBLEM_RESPONSES)


@router.post("", response_model=AmsOut, summary="AMS volume and largest moments along directions")
def ams_summary(body: AmsRequest) -> AmsOut:
    return ams.summarize(body.to_problem(), body.directions)
