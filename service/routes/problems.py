"""Documentation of the problem types, at the URIs their ``type`` member points to."""

from __future__ import annotations

from fastapi import APIRouter
from pydantic import BaseModel

from ..problem_types import PROBLEM_TYPES
from ..problems import HTTPProblem, problem_responses

router = APIRouter(prefix="/problems", tags=["problems"])


class ProblemTypeInfo(BaseModel):
    type: str
    status: int
    title: str
    description: str


def _info(slug: str) -> ProblemTypeInfo:
    kind = PROBLEM_TYPES[slug]
    return ProblemTypeInfo(type=kind.uri, status=kind.status, title=kind.title,
                           description=kind.description)


@router.get("", response_model=list[ProblemTypeInfo], summary="All problem types")
def list_problem_types() -> list[ProblemTypeInfo]:
    return [_info(slug) for slug in sorted(PROBLEM_TYPES)]


@router.get("/{slug}", response_model=ProblemTypeInfo, summary="One problem type",
            responses=problem_responses("not-found"))
def get_problem_type(slug: str) -> ProblemTypeInfo:
    if slug not in PROBLEM_TYPES:
        raise HTTPProblem("not-found", f"no problem type {slug!r}")
    return _info(slug)
