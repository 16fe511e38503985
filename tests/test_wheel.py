"""The built wheel, installed outside the checkout, trains, sweeps, evaluates and plots from an empty folder."""
import os
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

pytestmark = pytest.mark.slow


def _run(*command: str | Path, cwd: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "MUJOCO_GL": "osmesa", "OMP_NUM_THREADS": "1"}
    env.pop("PYTHONPATH", None)
    result = subprocess.run([str(part) for part in command], cwd=cwd, env=env, capture_output=True, text=True,
                            timeout=900)
    assert result.returncode == 0, f"{command}:\n{result.stdout[-2000:]}\n{result.stderr[-4000:]}"
    return result


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> Path:
    """A venv holding the wheel alone: the package's own files come from the wheel, never from the checkout."""
    root = tmp_path_factory.mktemp("wheel")
    dist = root / "dist"
    _run(sys.executable, "-m", "build", "--sdist", "--wheel", "--outdir", dist, REPO, cwd=root)
    _run(sys.executable, "-m", "twine", "check", "--strict", *sorted(dist.iterdir()), cwd=root)
    venv = root / "venv"
    _run(sys.executable, "-m", "venv", venv, cwd=root)
    python = venv / "bin" / "python"
    (wheel,) = dist.glob("torchrl_cebp-*.whl")
    _run(python, "-m", "pip", "install", "-q", "--no-deps", wheel, cwd=root)
    # The dependencies (torch alone is gigabytes) come from the test's own environment, appended after the venv's
    # site-packages: a path a .pth file names runs none of that folder's own .pth files, so the checkout's editable
    # install stays out.
    venv_site = Path(_run(python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])", cwd=root)
                     .stdout.strip())
    (venv_site / "test_dependencies.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    return venv / "bin"


def test_the_wheel_holds_the_configs_and_policies(installed):
    (wheel,) = (installed.parent.parent / "dist").glob("torchrl_cebp-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    configs = {path.relative_to(REPO).as_posix() for path in (REPO / "torchrl_cebp" / "conf").rglob("*.yaml")}
    assert configs <= set(names) and len(configs) > 25
    assert {"torchrl_cebp/agents/policies/push.pt", "torchrl_cebp/agents/policies/pick_place.pt",
            "torchrl_cebp/sim2real/policies/franka_pick_place_cebp.pt"} <= set(names)


def test_the_installed_commands_train_sweep_evaluate_and_plot_from_an_empty_folder(installed, tmp_path):
    where = _run(installed / "python", "-c", "import torchrl_cebp; print(torchrl_cebp.__file__)", cwd=tmp_path)
    assert str(installed.parent) in where.stdout and str(REPO) not in where.stdout
    for command in ("torchrl-cebp-train", "torchrl-cebp-evaluate", "torchrl-cebp-plot", "torchrl-cebp-sim2real"):
        assert _run(installed / command, "--version", cwd=tmp_path).stdout.strip() == "torchrl-cebp 0.1.0"
    quick = ("preset=quick", "epochs=1", "cycles_per_epoch=2")
    # A sampler config of the user's own, through Hydra's search path, as docs/training.md shows it.
    (tmp_path / "my_conf" / "sampler").mkdir(parents=True)
    (tmp_path / "my_conf" / "sampler" / "my_cebp.yaml").write_text(
        "_target_: torchrl_cebp.replay.samplers.CEBPSampler\nscale: 100.0\ntemperature: 0.1\nbeta: 0.5\n")
    trained = _run(installed / "python", "-m", "torchrl_cebp.train", *quick, "hydra.run.dir=runs/single",
                   f"hydra.searchpath=[file://{tmp_path / 'my_conf'}]", "sampler=my_cebp", cwd=tmp_path)
    assert "per-epoch results: " in trained.stdout and (tmp_path / "runs/single/progress.csv").is_file()
    assert "sampler=my_cebp" in (tmp_path / "runs/single/.hydra/overrides.yaml").read_text()
    _run(installed / "torchrl-cebp-train", "-m", "sampler=her,cebp", *quick, cwd=tmp_path)
    for sampler in ("her", "cebp"):
        assert (tmp_path / f"runs/push-standard/{sampler}/quick/seed0/progress.csv").is_file()
    evaluated = _run(installed / "torchrl-cebp-evaluate", "--task", "push", "--episodes", "2", cwd=tmp_path)
    assert "success" in evaluated.stdout.lower()
    _run(installed / "torchrl-cebp-plot", "runs", "--out", "curves.png", cwd=tmp_path)
    assert (tmp_path / "curves.png").stat().st_size > 10_000
