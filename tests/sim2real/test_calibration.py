import json

import pytest

from torchrl_cebp.sim2real import TableCalibration

FOUR = {0: (0.3, -0.3), 1: (0.3, 0.3), 2: (0.7, 0.3), 3: (0.7, -0.3)}


@pytest.mark.parametrize("suffix", [".yaml", ".yml", ".json"])
def test_round_trip(tmp_path, calibration, suffix):
    path = tmp_path / f"table{suffix}"
    calibration.save(path)
    assert TableCalibration.load(path) == calibration


def test_json_written_by_hand_is_normalised(tmp_path):
    path = tmp_path / "table.json"
    path.write_text(json.dumps({"marker_positions": {str(k): list(v) for k, v in FOUR.items()}}))
    loaded = TableCalibration.load(path)
    assert loaded.marker_positions == FOUR
    assert loaded.aruco_dictionary == "DICT_4X4_50" and loaded.table_height == 0.0


def test_fewer_than_four_markers():
    with pytest.raises(ValueError, match="at least 4 markers.*got 3"):
        TableCalibration({0: (0.3, -0.3), 1: (0.3, 0.3), 2: (0.7, 0.3)})


def test_unknown_dictionary_lists_valid_names():
    with pytest.raises(ValueError, match="Unknown ArUco dictionary 'DICT_9X9_50'.*DICT_4X4_50.*DICT_ARUCO_ORIGINAL"):
        TableCalibration(FOUR, aruco_dictionary="DICT_9X9_50")


def test_collinear_markers():
    with pytest.raises(ValueError, match="collinear"):
        TableCalibration({0: (0.3, 0.0), 1: (0.4, 0.0), 2: (0.5, 0.0), 3: (0.6, 0.0)})


def test_non_finite_values():
    with pytest.raises(ValueError, match="finite"):
        TableCalibration({**FOUR, 3: (float("nan"), 0.0)})


def test_unknown_field_and_file_type(tmp_path):
    path = tmp_path / "table.yaml"
    path.write_text("marker_positions: {0: [0.3, -0.3], 1: [0.3, 0.3], 2: [0.7, 0.3], 3: [0.7, -0.3]}\ncam: 1\n")
    with pytest.raises(ValueError, match=r"Unknown calibration fields \['cam'\]"):
        TableCalibration.load(path)
    with pytest.raises(ValueError, match="end in"):
        TableCalibration(FOUR).save(tmp_path / "table.txt")
