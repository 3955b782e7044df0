"""The adequacy table prints what a fit's figures mean, not what rounding made of them."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

from identification.methods.adequacy import FIN_ERROR_MATERIAL
from identification.reports.tables import adequacy_table


def _fit(share: float | None, ratio: float | None) -> Any:
    adequacy: dict[str, Any] = {
        "rate_r2": 0.986,
        "ahead_r2": 0.986,
        "fin_share": share,
        "fin_error_ratio": ratio,
        "ud_range_fraction": 0.0,
        "alpha_rel_se": 0.001,
        "verdict": "good",
        "reasons": [],
    }
    return SimpleNamespace(metrics={"adequacy": adequacy})


def _share_cell(share: float | None, ratio: float | None) -> str:
    row = adequacy_table({"ml": {"constant": _fit(share, ratio)}}).splitlines()[1]
    return row.split()[4] if share is not None else row


def test_a_share_of_a_u_d_too_small_to_matter_is_printed_as_noise() -> None:
    # u_d's SD a thousandth of the fin's: a share of 0.58 of it is rounding noise (the same
    # fit read 0.00 on one machine and 0.58 on another).
    tiny = 0.001
    assert _share_cell(0.58, (0.58**0.5) * tiny) == "noise"
    # Just above the material size, the share is the figure itself.
    above = 1.01 * FIN_ERROR_MATERIAL
    assert _share_cell(0.04, (0.04**0.5) * above) == "0.04"
    assert _share_cell(0.0, 0.0) == "0.00"  # nothing explained: no size to judge, shown as is
    # A flight fit has no share: the cell is blank.
    assert "noise" not in _share_cell(None, None)
