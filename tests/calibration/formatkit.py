"""Helpers of the exact format tests: an error caught whole, and compared whole."""

from __future__ import annotations

import pytest

from calibration import CalibrationError


def raised(fn, *args, **kwargs) -> CalibrationError:
    """The CalibrationError ``fn(*args, **kwargs)`` raises (the test fails if it raises none)."""
    with pytest.raises(CalibrationError) as info:
        fn(*args, **kwargs)
    return info.value


def assert_error(exc: CalibrationError, detail: str, *, camera=None, field=None, file=None) -> None:
    """The whole error as a user reads it: its detail, camera, field and file (None: none named)."""
    assert (exc.detail, exc.camera, exc.field) == (detail, camera, field)
    assert exc.file == (None if file is None else str(file))
