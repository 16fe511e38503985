"""A damaged checkpoint costs one epoch: resume falls back to the previous epoch's checkpoint, and says so."""
import logging
import math
import re
import subprocess
import sys
import zipfile

import hydra
import pytest
from omegaconf import OmegaConf

from tests.tiny_run import REPO, TINY, TINY_RUN, config, copy_run, rows
from torchrl_cebp.training import train
from torchrl_cebp.training.checkpoint import (
    BEST_POLICY_NAME, CHECKPOINT_FORMAT, CHECKPOINT_NAME, PREVIOUS_CHECKPOINT_NAME, BestPolicy, RunCheckpoints,
    UnreadableFileError, load_checkpoint, load_file, restore_training_state, save_checkpoint,
)
from torchrl_cebp.training.config import ConfigError, with_legacy_defaults


def truncate(path):
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])


def empty(path):
    path.write_bytes(b"")


def not_a_zip(path):
    path.write_text("epoch,test_success\n0,0.5\n")  # e.g. a CSV copied over it


def removed(path):  # a crash between the two renames of a save
    path.unlink()


DAMAGE = {
    truncate: "it is not a complete file of torch.save",
    empty: r"it is empty \(0 bytes\)",
    not_a_zip: r"it is not a complete file of torch.save \(25 bytes",
    removed: "there is no such file",
}


def test_a_run_keeps_the_previous_epochs_checkpoint_beside_the_newest(tiny_run):
    assert load_file(tiny_run / CHECKPOINT_NAME)["epoch"] == 1
    assert load_file(tiny_run / PREVIOUS_CHECKPOINT_NAME)["epoch"] == 0
    assert not list(tiny_run.glob("*.tmp"))


@pytest.mark.parametrize("damage", DAMAGE, ids=lambda damage: damage.__name__)
def test_a_damaged_newest_checkpoint_is_named_and_the_previous_one_loads(tiny_run, tmp_path, caplog, damage):
    run_dir = copy_run(tiny_run, tmp_path / "run")
    damage(run_dir / CHECKPOINT_NAME)
    with caplog.at_level(logging.WARNING):
        state = RunCheckpoints(run_dir).load()
    assert state["epoch"] == 0
    [record] = caplog.records
    assert "\n" not in record.getMessage()
    assert record.getMessage().startswith(f"{run_dir / CHECKPOINT_NAME} does not load: ")
    assert record.getMessage().endswith(
        f"; resuming from {PREVIOUS_CHECKPOINT_NAME} (epoch 0) instead, which repeats 1 epoch (epoch 1)")
    assert record.levelno == logging.WARNING and re.search(DAMAGE[damage], record.getMessage())


def test_a_resume_past_a_truncated_checkpoint_repeats_one_epoch_as_the_run_had_it(tiny_run, tmp_path, caplog):
    run_dir = copy_run(tiny_run, tmp_path / "run")
    truncate(run_dir / CHECKPOINT_NAME)
    with caplog.at_level(logging.WARNING):
        log = rows(train(config(*TINY_RUN, "epochs=3", "resume=true"), run_dir))
    assert [record.getMessage().split(" does not load: ")[0] for record in caplog.records
            if "does not load" in record.getMessage()] == [str(run_dir / CHECKPOINT_NAME)]
    # The CSV holds each epoch once, and the repeated epoch 1 is the one the run first trained (same streams).
    assert [row["epoch"] for row in log] == ["0", "1", "2"]
    for key in ("test_success", "loss_actor", "loss_value", "q_mean"):
        assert [row[key] for row in log[:2]] == [row[key] for row in rows(tiny_run / "progress.csv")]
    # The damaged file was overwritten, never kept as the previous one: the pair is whole again.
    assert load_file(run_dir / CHECKPOINT_NAME)["epoch"] == 2
    assert load_file(run_dir / PREVIOUS_CHECKPOINT_NAME)["epoch"] == 1


def test_when_neither_checkpoint_loads_both_are_named(tiny_run, tmp_path):
    run_dir = copy_run(tiny_run, tmp_path / "run")
    truncate(run_dir / CHECKPOINT_NAME)
    truncate(run_dir / PREVIOUS_CHECKPOINT_NAME)
    with pytest.raises(UnreadableFileError) as raised:
        RunCheckpoints(run_dir).load()
    message = str(raised.value)
    assert message.startswith(f"no checkpoint of {run_dir} loads: ")
    assert f"{run_dir / CHECKPOINT_NAME} does not load: it is not a complete file" in message
    assert f"{run_dir / PREVIOUS_CHECKPOINT_NAME} does not load: it is not a complete file" in message
    assert "\n" not in message


def test_train_py_exits_with_one_line_and_no_stack_trace_when_neither_checkpoint_loads(tiny_run, tmp_path):
    run_dir = copy_run(tiny_run, tmp_path / "run")
    empty(run_dir / CHECKPOINT_NAME)
    not_a_zip(run_dir / PREVIOUS_CHECKPOINT_NAME)
    done = subprocess.run([sys.executable, "train.py", *TINY, *TINY_RUN, "resume=true", f"hydra.run.dir={run_dir}"],
                          cwd=REPO, capture_output=True, text=True, timeout=300)
    assert done.returncode == 1
    assert "Traceback" not in done.stderr
    error_lines = [line for line in done.stderr.splitlines() if line.startswith("error: ")]
    assert error_lines == [
        f"error: no checkpoint of {run_dir} loads: {run_dir / CHECKPOINT_NAME} does not load: it is empty (0 bytes); "
        f"{run_dir / PREVIOUS_CHECKPOINT_NAME} does not load: it is not a complete file of torch.save "
        "(25 bytes: truncated, or another format)"
    ]
    assert (run_dir / "progress.csv").read_text() == (tiny_run / "progress.csv").read_text()  # nothing rewritten


def test_a_save_that_fails_midway_leaves_both_checkpoints_as_they_were(tmp_path):
    checkpoints = RunCheckpoints(tmp_path)
    checkpoints.save({"epoch": 0})
    checkpoints.save({"epoch": 1})
    (tmp_path / "checkpoint.tmp").mkdir()  # the temporary file cannot be written
    with pytest.raises(RuntimeError, match="Is a directory"):
        checkpoints.save({"epoch": 2})
    assert [load_file(tmp_path / name)["epoch"] for name in (CHECKPOINT_NAME, PREVIOUS_CHECKPOINT_NAME)] == [1, 0]


@pytest.mark.parametrize("damage", ["empty", "truncated"])
def test_a_damaged_best_policy_does_not_stop_a_resume(tmp_path, caplog, damage):
    best = tmp_path / BEST_POLICY_NAME
    best.write_bytes(b"" if damage == "empty" else b"PK\x03\x04" + b"\x00" * 100)
    with caplog.at_level(logging.WARNING):
        restored = BestPolicy(tmp_path, resume=True)
    assert restored.test_success == -math.inf  # the next epoch's policy is offered as the best so far
    assert str(best) in caplog.text and "the run's next policy replaces it" in caplog.text


def test_a_checkpoint_naming_the_samplers_former_module_resumes_with_the_same_sampler():
    saved = {"sampler": {"_target_": "torchrl_cebp.samplers.InitialCEBPSampler", "beta": 0.7}}
    assert with_legacy_defaults(saved)["sampler"] == {
        "_target_": "torchrl_cebp.replay.samplers.InitialCEBPSampler", "beta": 0.7}


def test_every_reader_of_an_older_checkpoint_gets_the_samplers_current_module(tmp_path):
    saved = {"epoch": 3, "config": {"sampler": {"_target_": "torchrl_cebp.samplers.InitialCEBPSampler", "beta": 0.7}}}
    save_checkpoint(saved, tmp_path)
    sampler = load_checkpoint(tmp_path)["config"]["sampler"]  # what compare_draws and diagnose_franka build from
    assert hydra.utils.instantiate(sampler).beta == 0.7


def test_save_checkpoint_after_a_fallback_keeps_the_previous_file_that_loaded(tmp_path):
    save_checkpoint({"epoch": 0}, tmp_path)
    save_checkpoint({"epoch": 1}, tmp_path)
    with zipfile.ZipFile(tmp_path / CHECKPOINT_NAME, "w") as damaged:  # a whole zip, but no file of torch.save
        damaged.writestr("checkpoint/data.pkl", b"not a pickle")
    assert load_checkpoint(tmp_path)["epoch"] == 0  # falls back...
    save_checkpoint({"epoch": 1}, tmp_path)  # ...and the run's next save, through the exported pair, keeps it
    assert [load_file(tmp_path / name)["epoch"] for name in (CHECKPOINT_NAME, PREVIOUS_CHECKPOINT_NAME)] == [1, 0]
    save_checkpoint({"epoch": 2}, tmp_path)  # the whole newest becomes the previous one again
    assert [load_file(tmp_path / name)["epoch"] for name in (CHECKPOINT_NAME, PREVIOUS_CHECKPOINT_NAME)] == [2, 1]


def test_a_resume_with_another_sampler_is_refused_naming_a_new_run_folder():
    saved = {"format": CHECKPOINT_FORMAT, "config": OmegaConf.to_container(config(*TINY_RUN), resolve=True)}
    with pytest.raises(ConfigError, match=re.escape("a run with another sampler is a new run: give it a new run "
                                                    "folder (hydra.run.dir=...)")) as refused:
        restore_training_state(saved, config("sampler=cper", "env=push"), None, None, None, None)
    assert "this config has sampler._target_='torchrl_cebp.replay.samplers.CPERSampler'" in str(refused.value)
    with pytest.raises(ConfigError) as refused:  # another setting of the same sampler: no new folder named
        restore_training_state(saved, config(*TINY_RUN, "seed=7"), None, None, None, None)
    assert "new run folder" not in str(refused.value)
