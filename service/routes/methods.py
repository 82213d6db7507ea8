"""What the service can compute."""

from __future__ import annotations

from fastapi import APIRouter

from ..schemas import MethodsResponse, methods_response

router = APIRouter(prefix="/v1", tags=["methods"])


@router.get("/methods", response_model=MethodsResponse,
            summary="Neighborhood methods, fit models and their parameters")
def list_methods() -> MethodsResponse:
    """Every method with its parameters (type, default, bounds, help), the fit models with
    theirs, the orientations, and the input and result formats."""
    return methods_response()
