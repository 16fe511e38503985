"""Fixtures shared by the Sim2Real tests."""

import pytest

from torchrl_cebp.sim2real import TableCalibration


@pytest.fixture
def calibration() -> TableCalibration:
    return TableCalibration(
        marker_positions={0: (0.3, -0.3), 1: (0.3, 0.3), 2: (0.7, 0.3), 3: (0.7, -0.3)},
        aruco_dictionary="DICT_4X4_50",
        table_height=0.02,
    )
