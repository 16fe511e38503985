"""Success curves of a sweep: interquartile mean (IQM) over seeds with a 95% bootstrap interval, per method and task.

    python -m torchrl_cebp.plot runs                      # writes runs/test_success.png
    python -m torchrl_cebp.plot runs --out fig.png --metric test_success --title "FetchPush"
    python -m torchrl_cebp.plot runs --table 5 10         # and prints a Markdown table after 5 and 10 epochs
    python -m torchrl_cebp.plot runs --table 5 10 --improvement-at 10   # and P(method > HER) after 10 epochs
    python -m torchrl_cebp.plot runs --table 10 15 --improvement-at 10 15   # P(method > HER) after 10 and after 15
    python -m torchrl_cebp.plot runs --table 10 --mean-over 6 10   # and each seed's mean over epochs 6-10
    python -m torchrl_cebp.plot runs --panels pick_place-standard push-standard --reference docs/results/paper_fig2.csv
    python -m torchrl_cebp.plot runs --configurations 'her/*' 'cper/*'   # these methods only
    python -m torchrl_cebp.plot runs --panels push-standard-temperature --against 'cebp_T(.+)/paper-per_worker' \
        --at 10 12 --against-references push-standard/her/paper   # success after 10 and 12 epochs against T
    python -m torchrl_cebp.plot runs --panels push-standard-temperature --against 'cebp_T(.+)/paper-per_worker' \
        --at 10 12 --against-references push-standard/her/paper --parameter-values 0.01 0.1 1 \
        --table 10 12 --improvement-at 12 --parameter-baseline 0.01   # and a table: P(> T = 0.01), P(> HER)

The statistics follow rliable's conventions (:mod:`torchrl_cebp.stats`): IQM, stratified-bootstrap
95% confidence intervals, and the probability of improvement over a baseline configuration.

A run is any folder holding a ``progress.csv``; runs are grouped by their parent folder (the
seeds of one configuration), and one panel is drawn per top-level folder under the sweep root
(``<task>-<goal_space>[-<robot>]`` with the trainer's layout
``runs/<task>-<goal_space>[-<robot>]/<sampler>/<preset>/seed<k>``). Figures and tables name a configuration
``<sampler>/<variant>`` by its method (:func:`method_label`, from :data:`SAMPLER_NAMES` and :data:`VARIANT_NAMES`)
and a panel by its task in words (:func:`panel_title`); tables give the run folder beside the method.
"""
from __future__ import annotations

import argparse
import csv
import fnmatch
import re
import textwrap
from collections import defaultdict
from collections.abc import Collection, Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.ticker import MaxNLocator, NullLocator  # noqa: E402
import numpy as np  # noqa: E402

import torchrl_cebp  # noqa: E402
from torchrl_cebp.stats import (  # noqa: E402
    iqm,
    probability_of_improvement,
    probability_of_improvement_ci,
    stratified_bootstrap_ci,
)
from torchrl_cebp.training.metrics import CSV_NAME  # noqa: E402


def read_curve(path: Path, metric: str) -> np.ndarray:
    """The ``metric`` column of one run's CSV, indexed by epoch.

    Args:
        path (Path): the run's ``progress.csv``.
        metric (str): the column to read.

    Returns:
        the column's values, ordered by the ``epoch`` column.

    Raises:
        KeyError: the CSV has no column ``metric``.

    Examples:
        >>> import tempfile
        >>> with tempfile.TemporaryDirectory() as d:
        ...     p = Path(d) / "progress.csv"
        ...     _ = p.write_text("epoch,test_success\\n0,0.1\\n1,0.3\\n")
        ...     read_curve(p, "test_success").tolist()
        [0.1, 0.3]
    """
    with path.open(newline="") as f:
        rows = list(csv.DictReader(f))
    if rows and metric not in rows[0]:
        raise KeyError(f"{path} has no column {metric!r}; columns: {sorted(rows[0])}")
    return np.array([float(row[metric]) for row in sorted(rows, key=lambda r: int(r["epoch"]))])


def collect_sweep(root: Path, metric: str) -> dict[str, dict[str, list[np.ndarray]]]:
    """``{panel: {curve label: [one curve per seed]}}`` for every ``progress.csv`` under ``root``.

    In the trainer's layout ``<task>/<sampler>/<preset>/seed<k>`` the panel is the task folder, whether
    ``root`` holds several tasks or is one task's folder; runs laid out otherwise share one panel named
    after ``root``, labelled by their folders below it. Runs that do not log ``metric`` (e.g. IS weights,
    under a sampler without them) are left out.

    Args:
        root (Path): the sweep folder, searched recursively.
        metric (str): the CSV column to collect.

    Raises:
        KeyError: no run logs ``metric``.
    """
    groups: dict[str, dict[str, list[np.ndarray]]] = defaultdict(lambda: defaultdict(list))
    first_missing: KeyError | None = None
    for path in sorted(root.rglob(CSV_NAME)):
        configuration_folder = path.parent.parent
        task_folder = configuration_folder.parent.parent
        if task_folder.is_relative_to(root):
            panel, label_root = task_folder.name, task_folder
        else:
            panel, label_root = root.name, root
        label = "/".join(configuration_folder.relative_to(label_root).parts) or path.parent.name
        try:
            curve = read_curve(path, metric)
        except KeyError as error:
            first_missing = first_missing or error
            continue
        if curve.size:
            groups[panel][label].append(curve)
    if first_missing is not None and not groups:
        raise first_missing
    return groups


SAMPLER_NAMES = {
    "her": "HER",
    "cebp_initial": "CEBP (Initial commit)",
    "cebp": "CEBP (paper form)",
    "cebp_released": "CEBP (released code)",
    "cper": "CPER",
    "per": "PER",
    "ebp": "EBP",
    "mep": "MEP",
}
"""The method a sampler folder runs, as readers know it; legends and tables list methods in this order."""
TEMPERATURE_FOLDER = re.compile(r"cebp_T(?P<temperature>.+)")  # the temperature ablation's folders, cebp_T<T>
VARIANT_NAMES = {"wnorm": "normalised loss", "beta0": "no IS weights", "her_past": "'past' HER draw"}
"""What a part of a run folder's variant (``<preset>[-per_worker][-her_past][-wnorm][-beta0]``) changes."""
PUBLISHED_VARIANT_PARTS = {"cper": "her_past"}
"""A sampler's published form, named by nothing in its labels; without it the label says what ran instead."""
SUPERSEDED = ("merged buffer", "normalised loss", "'future' HER draw")
"""Qualifiers of runs that an emulation fix replaced; their labels say "(superseded)"."""
PAPER_PRESET = "paper"  # 8 workers, so a prioritised sampler's run without -per_worker drew from one merged buffer
TASK_NAMES = {
    "push": "Push", "pick_place": "PickAndPlace", "slide": "Slide", "franka_pick_place": "Franka PickAndPlace"
}
PANEL_PART_NAMES = {
    "standard": "standard goals",
    "extended": "extended goals",
    "joint": "joint control",
    "tableblind": "table-blind pads",
    "grasped50": "half the training episodes start grasped",
}


def sampler_name(sampler: str) -> str:
    """The method a sampler folder runs (:data:`SAMPLER_NAMES`); an unknown folder keeps its name.

    Args:
        sampler (str): the sampler folder, e.g. ``"cebp_initial"`` or ``"cebp_T0.01"``.

    Examples:
        >>> sampler_name("cebp_initial"), sampler_name("cebp_T0.01"), sampler_name("my_sampler")
        ('CEBP (Initial commit)', 'CEBP (paper form), T = 0.01', 'my_sampler')
    """
    if sampler in SAMPLER_NAMES:
        return SAMPLER_NAMES[sampler]
    temperature = TEMPERATURE_FOLDER.fullmatch(sampler)
    if temperature:
        return f"{SAMPLER_NAMES['cebp']}, T = {temperature['temperature']}"
    return sampler


def method_label(label: str) -> str:
    """The name a reader knows for a configuration label ``<sampler>/<variant>`` (a run folder below its task).

    The sampler folder names the method (:data:`SAMPLER_NAMES`); the variant's parts say what differs from the
    method as the comparison runs it (the paper preset, per-worker replay, baselines' critic loss, the sampler's
    published HER draw), and a superseded emulation (:data:`SUPERSEDED`) is marked so. Parts this mapping does not
    know are kept as they are, so that no run is mislabelled.

    Args:
        label (str): the configuration label, e.g. ``"cebp_initial/paper-per_worker"``.

    Examples:
        >>> method_label("her/paper"), method_label("cebp_initial/paper-per_worker")
        ('HER', 'CEBP (Initial commit)')
        >>> method_label("cebp_initial/paper-per_worker-beta0")
        'CEBP (Initial commit), no IS weights'
        >>> method_label("cebp/paper-wnorm")
        'CEBP (paper form), merged buffer, normalised loss (superseded)'
        >>> method_label("cper/paper-per_worker-her_past"), method_label("cper/paper-per_worker")
        ('CPER', "CPER, 'future' HER draw (superseded)")
        >>> method_label("mep/quick-bf16")
        'MEP, quick preset, bf16'
    """
    sampler, _, variant = label.partition("/")
    preset, *parts = variant.split("-") if variant else ("",)
    qualifiers = [] if preset in ("", PAPER_PRESET) else [f"{preset} preset"]
    if preset == PAPER_PRESET and sampler != "her" and "per_worker" not in parts:
        qualifiers.append("merged buffer")
    published = PUBLISHED_VARIANT_PARTS.get(sampler)
    if published is not None and published not in parts:
        qualifiers.append("'future' HER draw")
    qualifiers += [VARIANT_NAMES.get(part, part) for part in parts if part not in ("per_worker", published)]
    superseded = " (superseded)" if any(q in SUPERSEDED for q in qualifiers) else ""
    return ", ".join([sampler_name(sampler), *qualifiers]) + superseded


def method_order(label: str) -> tuple[int, str]:
    """Sort key of configuration labels: the order of :data:`SAMPLER_NAMES` (HER first), then the folder.

    Args:
        label (str): the configuration label ``<sampler>/<variant>``.

    Examples:
        >>> sorted(["mep/paper", "her/paper", "mine/paper"], key=method_order)
        ['her/paper', 'mep/paper', 'mine/paper']
    """
    samplers = list(SAMPLER_NAMES)
    sampler = sampler_of(label)
    return (samplers.index(sampler) if sampler in samplers else len(samplers), label)


def panel_title(panel: str) -> str:
    """A task folder ``<task>-<goal_space>[-<robot>][-T<steps>]...`` in words; parts it does not know stay as they are.

    Args:
        panel (str): the task folder; one whose task is unknown is returned as it is.

    Examples:
        >>> panel_title("push-extended-joint-tableblind")
        'Push: extended goals, joint control, table-blind pads'
        >>> panel_title("slide-standard-T70"), panel_title("learning")
        ('Slide: standard goals, 70-step episodes', 'learning')
    """
    task, *parts = panel.split("-")
    if task not in TASK_NAMES:
        return panel
    words = [
        f"{part[1:]}-step episodes" if re.fullmatch(r"T\d+", part) else PANEL_PART_NAMES.get(part, part)
        for part in parts
    ]
    return TASK_NAMES[task] + (": " + ", ".join(words) if words else "")


def padded(curves: list[np.ndarray]) -> np.ndarray:
    """The seeds' curves as rows ``[seeds, epochs]``, NaN after the last epoch a seed reached.

    Args:
        curves (list of np.ndarray): one curve per seed, of any lengths (at least one curve).

    Examples:
        >>> padded([np.array([0.1, 0.2]), np.array([0.3])]).tolist()
        [[0.1, 0.2], [0.3, nan]]
    """
    length = max(len(c) for c in curves)
    out = np.full((len(curves), length), np.nan)
    for i, curve in enumerate(curves):
        out[i, : len(curve)] = curve
    return out


def iqm_band(curves: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per epoch, over the seeds that reached it: the IQM, its 95% bootstrap interval and the seed count.

    Args:
        curves (list of np.ndarray): one curve per seed, indexed by epoch.

    Returns:
        ``(iqm, low, high, seeds)``, each of shape ``[epochs]``.

    Examples:
        >>> mean, low, high, seeds = iqm_band([np.array([0.0, 1.0]), np.array([1.0])])
        >>> mean.tolist(), seeds.tolist()
        ([0.5, 1.0], [2, 1])
    """
    table = padded(curves)
    mean, low, high, seeds = (np.empty(table.shape[1]) for _ in range(4))
    for epoch, column in enumerate(table.T):
        values = column[~np.isnan(column)]
        mean[epoch] = iqm(values)
        low[epoch], high[epoch] = stratified_bootstrap_ci(values)
        seeds[epoch] = values.size
    return mean, low, high, seeds.astype(int)


def seed_coverage(seeds_per_epoch: np.ndarray) -> str:
    """How many seeds each stretch of epochs (counted from 1) averages, for the legend.

    Args:
        seeds_per_epoch (np.ndarray): the seed count of each epoch, as :func:`iqm_band` returns it.

    Examples:
        >>> seed_coverage(np.array([3, 3, 3, 1]))
        '3 seeds to epoch 3, 1 seed to 4'
        >>> seed_coverage(np.array([2, 2]))
        '2 seeds'
    """
    stretches: list[tuple[int, int]] = []
    for epoch, n in enumerate(map(int, seeds_per_epoch), start=1):
        if stretches and stretches[-1][0] == n:
            stretches[-1] = (n, epoch)
        else:
            stretches.append((n, epoch))
    if len(stretches) == 1:
        return seed_count(stretches[0][0])
    return seed_count(stretches[0][0]) + f" to epoch {stretches[0][1]}" + "".join(
        f", {seed_count(n)} to {last}" for n, last in stretches[1:]
    )


def seed_count(n: int) -> str:
    """``"1 seed"``, ``"3 seeds"``: the count every legend entry and table cell names.

    Args:
        n (int): the number of seeds.

    Examples:
        >>> seed_count(1), seed_count(3)
        ('1 seed', '3 seeds')
    """
    return f"{n} seed{'s' * (n > 1)}"


REFERENCE_MARKERS = ("X", "*", "D", "P", "s", "^")
VARIANT_LINESTYLES = ("-", "--", "-.")
TAIL_LINESTYLE = ":"  # reserved for the epochs only some seeds reached
LEGEND_WIDTH = 55  # characters of a legend line, so that a legend stays as wide as its 5-inch panel


def sampler_of(label: str) -> str:
    """The sampler of a configuration label ``<sampler>/<variant>`` (or of a reference key ``<sampler>/<name>``).

    Args:
        label (str): the configuration label or reference key.

    Examples:
        >>> sampler_of("cebp_initial/paper-per_worker")
        'cebp_initial'
    """
    return label.split("/")[0]


def sampler_colours(samplers: Collection[str]) -> dict[str, str]:
    """One colour of matplotlib's cycle per sampler, fixed by :data:`SAMPLER_NAMES`' order (other samplers, sorted,
    after them), so that a method keeps its colour in every panel and every figure.

    Args:
        samplers (collection of str): the sampler folders to colour.

    Examples:
        >>> colours = sampler_colours({"her", "cebp"})
        >>> colours["cebp"] != colours["her"], colours["her"] == sampler_colours({"her", "per"})["her"]
        (True, True)
    """
    palette = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    order = [*SAMPLER_NAMES, *sorted(set(samplers) - set(SAMPLER_NAMES))]
    return {sampler: palette[order.index(sampler) % len(palette)] for sampler in samplers}


def variant_linestyles(labels: Collection[str]) -> dict[str, str]:
    """A line style per configuration label ``<sampler>/<variant>``: a sampler's variants take
    ``VARIANT_LINESTYLES`` in turn, the method as the comparison runs it (its label the method's bare name) first,
    so that one sampler's curves differ in style where they share a colour (a fourth variant repeats the first's
    style). The dotted style is kept for tails that only some seeds reached.

    Args:
        labels (collection of str): the configuration labels of one panel.

    Examples:
        >>> variant_linestyles(["her/paper", "cebp_initial/paper-per_worker-wnorm", "cebp_initial/paper-per_worker"])
        {'cebp_initial/paper-per_worker': '-', 'cebp_initial/paper-per_worker-wnorm': '--', 'her/paper': '-'}
    """
    by_sampler: dict[str, list[str]] = defaultdict(list)
    for label in sorted(labels, key=lambda label: (method_label(label) != sampler_name(sampler_of(label)), label)):
        by_sampler[sampler_of(label)].append(label)
    return dict(sorted(
        (label, VARIANT_LINESTYLES[i % len(VARIANT_LINESTYLES)])
        for variants in by_sampler.values() for i, label in enumerate(variants)
    ))


def select_configurations(
    groups: dict[str, dict[str, list]], patterns: Sequence[str] | None
) -> dict[str, dict[str, list]]:
    """``groups`` restricted to the configuration labels (``<sampler>/<variant>``) that match one of ``patterns``
    (shell wildcards, e.g. ``her/*``); panels left without a configuration are dropped.

    Args:
        groups (dict): ``{panel: {configuration label: curves}}``, as :func:`collect_sweep` returns it.
        patterns (sequence of str or None): shell patterns of the labels to keep; ``None`` keeps all.

    Raises:
        KeyError: a pattern matches no configuration.

    Examples:
        >>> groups = {"push-standard": {"her/paper": [], "cebp/paper-wnorm": []}, "slide-standard": {"cebp/paper": []}}
        >>> select_configurations(groups, ["her/*"])
        {'push-standard': {'her/paper': []}}
    """
    if patterns is None:
        return groups
    labels = {label for curves_by_label in groups.values() for label in curves_by_label}
    unmatched = [pattern for pattern in patterns if not fnmatch.filter(labels, pattern)]
    if unmatched:
        raise KeyError(f"no configuration matches {unmatched}; the configurations: {sorted(labels)}")
    kept = {
        panel: {label: curves for label, curves in curves_by_label.items()
                if any(fnmatch.fnmatchcase(label, pattern) for pattern in patterns)}
        for panel, curves_by_label in groups.items()
    }
    return {panel: curves_by_label for panel, curves_by_label in kept.items() if curves_by_label}


def select_panels(
    groups: dict[str, dict], panels: Sequence[str] | None, root: Path, may_be_empty: Collection[str] = ()
) -> dict[str, dict]:
    """``groups`` restricted to ``panels`` (task folders), in that order; all of them, sorted, for ``None``.

    Args:
        groups (dict): ``{panel: {configuration label: curves}}``, as :func:`collect_sweep` returns it.
        panels (sequence of str or None): the task folders to keep, in order; ``None`` keeps all, sorted.
        root (Path): the sweep folder, named by the error.
        may_be_empty (collection of str, optional): panels kept without runs, as ``{}`` (those with published
            values to mark). Defaults to none.

    Raises:
        KeyError: a panel of ``panels`` has no runs and is not in ``may_be_empty``.

    Examples:
        >>> groups = {"slide-standard": {"her/paper": []}, "push-standard": {"her/paper": []}}
        >>> list(select_panels(groups, None, Path("runs")))
        ['push-standard', 'slide-standard']
        >>> select_panels(groups, ["pick_place-standard"], Path("runs"), may_be_empty={"pick_place-standard"})
        {'pick_place-standard': {}}
    """
    if panels is None:
        return dict(sorted(groups.items()))
    missing = [panel for panel in panels if panel not in groups and panel not in may_be_empty]
    if missing:
        raise KeyError(f"no runs for panel(s) {missing} under {root}; its panels: {sorted(groups)}")
    return {panel: groups.get(panel, {}) for panel in panels}


def read_reference(path: str | Path) -> dict[str, dict[str, list[tuple[int, float]]]]:
    """Published values to mark on the panels, from a CSV with columns ``panel,sampler,name,epoch,value``.

    ``panel`` is a task folder (e.g. ``push-standard``), ``sampler`` the sampler folder whose colour the
    markers take, ``name`` the legend's name for the published curve, ``epoch`` the epochs trained.

    Args:
        path (str or Path): the CSV.

    Returns:
        ``{panel: {"<sampler>/<name>": [(epoch, value), ...]}}``.

    Example:
        >>> import tempfile, pathlib
        >>> with tempfile.TemporaryDirectory() as d:
        ...     path = pathlib.Path(d) / "paper.csv"
        ...     _ = path.write_text("panel,sampler,name,epoch,value\\npush-standard,her,HER (paper),10,0.5\\n")
        ...     read_reference(path)
        {'push-standard': {'her/HER (paper)': [(10, 0.5)]}}
    """
    reference: dict[str, dict[str, list[tuple[int, float]]]] = defaultdict(lambda: defaultdict(list))
    with Path(path).open(newline="") as f:
        for row in csv.DictReader(f):
            reference[row["panel"]][f"{row['sampler']}/{row['name']}"].append((int(row["epoch"]), float(row["value"])))
    return {panel: dict(curves) for panel, curves in reference.items()}


def caption(metric: str, reference_source: str | None) -> str:
    """What a figure's lines, bands, dotted tails and markers are, printed under it.

    Args:
        metric (str): the CSV column drawn.
        reference_source (str or None): where the published values marked come from; ``None`` when none are.

    Examples:
        >>> print(caption("test_success", "the paper's Fig. 2"))
        Lines: IQM of test success over the seeds the legend names; bands: 95% stratified-bootstrap CI; dotted: epochs that only some seeds reached. Markers: read off the paper's Fig. 2; its values past our last epoch are noted in the panel.
    """
    text = (f"Lines: IQM of {metric.replace('_', ' ')} over the seeds the legend names; bands: 95% stratified-bootstrap"
            " CI; dotted: epochs that only some seeds reached.")
    if reference_source is not None:
        text += f" Markers: read off {reference_source}; its values past our last epoch are noted in the panel."
    return text


def draw_sweep(
    root: str | Path,
    metric: str = "test_success",
    title: str | None = None,
    log_y: bool = False,
    panels: Sequence[str] | None = None,
    reference: str | Path | None = None,
    configurations: Sequence[str] | None = None,
    reference_panel: str | None = None,
    reference_source: str = "the paper's Fig. 2",
) -> plt.Figure:
    """One panel per task, one IQM line and 95% bootstrap band per configuration, named by its method
    (:func:`method_label`), with a caption (:func:`caption`) under the figure.

    A curve is solid with its band over the epochs all its seeds reached, and dotted, without a band, over those
    only some reached; the legend names how many seeds each stretch averages.

    A sampler keeps its colour in every panel and figure, and a published curve takes its sampler's colour; a
    sampler's variants in one panel (e.g. ``paper-per_worker`` and ``paper-per_worker-wnorm``) differ by line style.
    A metric whose values all lie in [0, 1] (a success rate, a fraction) is drawn on one shared scale, so
    that a task still near zero looks it. The x axis ends at the panel's last epoch: published values past it
    are listed in the panel, not drawn, so that they do not squeeze our curves.

    Args:
        root (str or Path): the sweep folder (see :func:`collect_sweep`).
        metric (str, optional): the CSV column drawn. Defaults to ``"test_success"``.
        title (str, optional): names the figure; with a single panel it replaces the panel's own title (its task
            in words, :func:`panel_title`), which is what a sweep root without a ``<task>-<goal_space>`` level
            (e.g. ``runs/learning``) needs. Defaults to ``None``.
        log_y (bool, optional): draws the metric on a log scale, for one that spans decades (IS weights, the
            effective fraction of the buffer drawn from). Defaults to ``False``.
        panels (sequence of str, optional): keeps those task folders only, in that order. Defaults to ``None``
            (all, sorted).
        reference (str or Path, optional): a CSV of published values (see :func:`read_reference`), marked in the
            colour of the sampler they belong to; a panel in ``panels`` with published values but no runs yet is
            drawn with the markers alone. Defaults to ``None``.
        configurations (sequence of str, optional): keeps the configuration labels that match one of these shell
            patterns (:func:`select_configurations`); only the published curves of the samplers drawn are then
            marked. Defaults to ``None`` (all).
        reference_panel (str, optional): marks every panel with that panel's published values (the paper's Push
            curves on each robot's Push). Defaults to ``None``.
        reference_source (str, optional): where the published values come from, for the caption. Defaults to
            ``"the paper's Fig. 2"``.

    Returns:
        the figure.

    Raises:
        FileNotFoundError: no run under ``root`` logs ``metric`` (or matches ``configurations``).
        KeyError: a panel or configuration asked for has no runs, or ``reference_panel`` no published values.

    Examples:
        >>> import tempfile
        >>> with tempfile.TemporaryDirectory() as d:
        ...     run = Path(d) / "push-standard" / "her" / "paper" / "seed0"
        ...     run.mkdir(parents=True)
        ...     _ = (run / CSV_NAME).write_text("epoch,test_success\\n0,0.1\\n1,0.4\\n")
        ...     fig = draw_sweep(d)
        >>> [ax.get_title() for ax in fig.axes]
        ['Push: standard goals']
        >>> plt.close(fig)
    """
    root = Path(root)
    groups = select_configurations(collect_sweep(root, metric), configurations)
    if not groups:
        raise FileNotFoundError(f"no {CSV_NAME} under {root}")
    published = read_reference(reference) if reference is not None else {}
    # A published curve keeps its marker in every panel and figure drawn from one reference.
    marker_of = {key: REFERENCE_MARKERS[i % len(REFERENCE_MARKERS)]
                 for i, key in enumerate(sorted({key for curves in published.values() for key in curves}))}
    if reference_panel is not None:
        if reference_panel not in published:
            raise KeyError(
                f"reference_panel={reference_panel!r} has no published values; those with: {sorted(published)}"
            )
        published = {panel: published[reference_panel] for panel in (panels or groups)}
    if configurations is not None:  # published curves of the methods drawn only
        drawn = {sampler_of(label) for curves_by_label in groups.values() for label in curves_by_label}
        published = {panel: {key: points for key, points in curves.items() if sampler_of(key) in drawn}
                     for panel, curves in published.items()}
    groups = select_panels(groups, panels, root, may_be_empty=published)
    sampler_colour = sampler_colours(
        {sampler_of(label) for panel, curves_by_label in groups.items()
         for label in [*curves_by_label, *published.get(panel, {})]}
    )
    values = np.concatenate([c for curves_by_label in groups.values() for cs in curves_by_label.values() for c in cs])
    fraction = bool(np.all((values >= 0) & (values <= 1)))
    # Legends sit below their panels, so that neither curves nor markers hide behind them.
    entries = max(  # legend lines: a long label (its seed counts ~25 characters) wraps
        sum(1 + (len(method_label(label)) + 25) // LEGEND_WIDTH for label in curves) + len(published.get(panel, {}))
        for panel, curves in groups.items()
    )
    width, height = 5 * len(groups), 3.8 + 0.17 * entries
    caption_lines = textwrap.wrap(caption(metric, reference_source if published else None), int(width * 15))
    caption_height = 0.16 * len(caption_lines) + 0.1
    fig, axes = plt.subplots(1, len(groups), figsize=(width, height + caption_height), squeeze=False, sharey=fraction)
    for ax, (panel, curves_by_label) in zip(axes[0], groups.items()):
        linestyle = variant_linestyles(curves_by_label)
        for label, curves in sorted(curves_by_label.items(), key=lambda item: method_order(item[0])):
            mean, low, high, seeds = iqm_band(curves)
            complete = min(len(curve) for curve in curves)
            epochs = np.arange(1, len(mean) + 1)
            colour = sampler_colour[sampler_of(label)]
            ax.plot(epochs[:complete], mean[:complete], color=colour, linestyle=linestyle[label],
                    marker="o" if complete == 1 else None,  # a line through one epoch draws nothing
                    label=textwrap.fill(f"{method_label(label)} ({seed_coverage(seeds)})", LEGEND_WIDTH))
            ax.fill_between(epochs[:complete], low[:complete], high[:complete], color=colour, alpha=0.2)
            if complete < len(mean):
                ax.plot(epochs[complete - 1:], mean[complete - 1:], color=colour, linestyle=TAIL_LINESTYLE,
                        linewidth=1.2)
        horizon = max(
            (len(curve) for curves in curves_by_label.values() for curve in curves),
            default=max((epoch for points in published.get(panel, {}).values() for epoch, _ in points), default=1),
        )
        if not curves_by_label:
            ax.text(0.5, 0.5, "no runs yet", transform=ax.transAxes, ha="center", va="center", color="grey")
        past_horizon = []
        for key, points in sorted(published.get(panel, {}).items()):
            sampler, _, name = key.partition("/")
            shown = [(epoch, value) for epoch, value in points if epoch <= horizon]
            past_horizon += [f"{name} {value:.2f} at epoch {epoch}" for epoch, value in points if epoch > horizon]
            if shown:
                epochs, values = zip(*shown)
                ax.plot(epochs, values, linestyle="none", marker=marker_of[key], markersize=8, markeredgecolor="black",
                        color=sampler_colour[sampler], label=name)
        if past_horizon:
            ax.text(0.02, 0.98, "Past this axis:\n" + "\n".join(past_horizon), transform=ax.transAxes, ha="left",
                    va="top", fontsize=7, bbox={"facecolor": "white", "alpha": 0.8, "edgecolor": "grey"})
        ax.set_title(textwrap.fill(title if title is not None and len(groups) == 1 else panel_title(panel), 50))
        if log_y:
            ax.set_yscale("log")
        ax.set_xlim(0, horizon + 0.5)
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.set_xlabel("epochs trained")
        ax.set_ylabel(f"{metric.replace('_', ' ')} (IQM, 95% CI)")
        ax.yaxis.set_tick_params(labelleft=True)
        ax.grid(alpha=0.3)
        # A pad in points (5 of the legend's 8-point font), not in axes fractions, so that the legend clears the
        # ticks and the x label at any panel height.
        ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, 0), borderaxespad=5)
    if title is not None and len(groups) > 1:
        fig.suptitle(title)
    fig.text(0.5, 0.01, "\n".join(caption_lines), ha="center", va="bottom", fontsize=8)
    fig.tight_layout(rect=(0, caption_height / (height + caption_height), 1, 1))
    return fig


def plot_sweep(
    root: str | Path,
    out: str | Path | None = None,
    metric: str = "test_success",
    title: str | None = None,
    log_y: bool = False,
    panels: Sequence[str] | None = None,
    reference: str | Path | None = None,
    configurations: Sequence[str] | None = None,
    reference_panel: str | None = None,
) -> Path:
    """Draws the sweep (:func:`draw_sweep`) to a PNG.

    Args:
        root (str or Path): the sweep folder.
        out (str or Path, optional): the PNG's path. Defaults to ``<root>/<metric>.png``.
        metric (str, optional): the CSV column drawn. Defaults to ``"test_success"``.
        title (str, optional): see :func:`draw_sweep`. Defaults to ``None``.
        log_y (bool, optional): see :func:`draw_sweep`. Defaults to ``False``.
        panels (sequence of str, optional): see :func:`draw_sweep`. Defaults to ``None``.
        reference (str or Path, optional): see :func:`draw_sweep`. Defaults to ``None``.
        configurations (sequence of str, optional): see :func:`draw_sweep`. Defaults to ``None``.
        reference_panel (str, optional): see :func:`draw_sweep`. Defaults to ``None``.

    Returns:
        the PNG's path.

    Examples:
        >>> import tempfile
        >>> with tempfile.TemporaryDirectory() as d:
        ...     run = Path(d) / "push-standard" / "her" / "paper" / "seed0"
        ...     run.mkdir(parents=True)
        ...     _ = (run / CSV_NAME).write_text("epoch,test_success\\n0,0.1\\n1,0.4\\n")
        ...     out = plot_sweep(d)
        ...     out.name, out.stat().st_size > 0
        ('test_success.png', True)
    """
    fig = draw_sweep(root, metric, title, log_y, panels, reference, configurations, reference_panel)
    out = Path(out) if out is not None else Path(root) / f"{metric}.png"
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return out


def values_at_epoch(curves: list[np.ndarray], n: int) -> list[float]:
    """Each seed's value after ``n`` epochs, over the seeds that got there.

    Args:
        curves (list of np.ndarray): one curve per seed, indexed by epoch.
        n (int): the epochs trained (from 1).

    Examples:
        >>> values_at_epoch([np.array([0.1, 0.2]), np.array([0.3])], 2)
        [0.2]
    """
    return [float(curve[n - 1]) for curve in curves if len(curve) >= n]


def seeds_summary(per_seed: list[float]) -> tuple[float, float, float, int]:
    """``(IQM, low, high, seeds)``: the IQM of the seeds' values, its 95% stratified-bootstrap CI and their number.

    Args:
        per_seed (list of float): one value per seed (at least one).

    Examples:
        >>> seeds_summary([0.25, 0.75])
        (0.5, 0.25, 0.75, 2)
    """
    low, high = stratified_bootstrap_ci(per_seed)
    return float(iqm(per_seed)), float(low), float(high), len(per_seed)


PARAMETER_DODGE = 0.03  # decades between the epoch counts' points at one parameter value, so error bars stay apart
REFERENCE_LINESTYLES = ("--", ":", "-.")


def parameter_runs(
    root: str | Path, panel: str, parameter_pattern: str, references: Sequence[str], metric: str = "test_success"
) -> tuple[dict[float, tuple[str, list[np.ndarray]]], dict[str, list[np.ndarray]]]:
    """The runs of a parameter study: ``({value: (configuration label, curves)}, {reference: curves})``, the values
    ascending and the references in the order given.

    Args:
        root (str or Path): the sweep folder (see :func:`collect_sweep`).
        panel (str): the task folder of the parameter's runs.
        parameter_pattern (str): a regular expression that matches, in full, the configuration labels of ``panel``
            that belong to the study; its first group is the parameter value.
        references (sequence of str): ``"<panel>/<sampler>/<variant>"`` of each reference configuration.
        metric (str, optional): the CSV column read. Defaults to ``"test_success"``.

    Raises:
        ValueError: a parameter value that is not a positive number (a log axis needs one), one value read from two
            configurations, or a pattern without a group.
        KeyError: ``panel`` or a reference has no runs, or ``parameter_pattern`` matches no configuration.

    Examples:
        >>> import tempfile
        >>> with tempfile.TemporaryDirectory() as d:
        ...     for label in ("sweep/cebp_T5/paper", "sweep/cebp_T0.1/paper", "base/her/paper"):
        ...         run = Path(d) / label / "seed0"
        ...         run.mkdir(parents=True)
        ...         _ = (run / CSV_NAME).write_text("epoch,test_success\\n0,0.5\\n")
        ...     by_value, references = parameter_runs(d, "sweep", r"cebp_T(.+)/paper", ["base/her/paper"])
        >>> {value: label for value, (label, _) in by_value.items()}, list(references)
        ({0.1: 'cebp_T0.1/paper', 5.0: 'cebp_T5/paper'}, ['base/her/paper'])
    """
    groups = collect_sweep(Path(root), metric)
    if panel not in groups:
        raise KeyError(f"no runs for panel {panel!r} under {root}; its panels: {sorted(groups)}")
    pattern = re.compile(parameter_pattern)
    if pattern.groups < 1:
        raise ValueError(f"parameter_pattern={parameter_pattern!r} has no group to read the parameter value from")
    by_value: dict[float, tuple[str, list[np.ndarray]]] = {}
    for label, curves in groups[panel].items():
        match = pattern.fullmatch(label)
        if match is None:
            continue
        try:
            value = float(match.group(1))
        except ValueError:
            value = float("nan")
        if not value > 0:
            raise ValueError(f"{label}: parameter {match.group(1)!r} is not a positive number, which a log axis needs")
        if value in by_value:
            raise ValueError(f"{by_value[value][0]} and {label} both read as parameter {value:g}; narrow the"
                             " pattern or move one of them")
        by_value[value] = (label, curves)
    if not by_value:
        raise KeyError(f"{parameter_pattern!r} matches no configuration of {panel}: {sorted(groups[panel])}")
    reference_curves = {}
    for reference in references:
        reference_panel, _, label = reference.partition("/")
        if label not in groups.get(reference_panel, {}):
            known = sorted(f"{p}/{known_label}" for p, labels in groups.items() for known_label in labels)
            raise KeyError(f"reference {reference!r} has no runs under {root}; the configurations: {known}")
        reference_curves[reference] = groups[reference_panel][label]
    return dict(sorted(by_value.items())), reference_curves


def plot_against_parameter(
    root: str | Path,
    panel: str,
    parameter_pattern: str,
    references: Sequence[str],
    epochs: Sequence[int],
    out: str | Path,
    metric: str = "test_success",
    parameter_name: str = "sigmoid temperature T",
    full_seeds: int | None = None,
    title: str | None = None,
    planned_values: Sequence[float] = (),
) -> dict[int, dict[str, dict]]:
    """The metric after each of ``epochs`` epochs against a parameter the run folders name, on a log x axis, with
    reference configurations as horizontal lines; written to a PNG.

    One line per epoch count joins the IQM over seeds at each parameter value, with its 95% stratified-bootstrap CI
    as error bars, each point annotated with its seed count (a hollow marker where it has fewer than
    ``full_seeds``). Each reference configuration is a horizontal line at its IQM, with a light band for its CI, in
    the colour of the epoch count. A parameter value whose runs have not reached an epoch count has no point there.

    Args:
        root (str or Path): the sweep folder (see :func:`collect_sweep`).
        panel (str): the task folder of the parameter's runs, e.g. ``"push-standard-temperature"``.
        parameter_pattern (str): a regular expression that matches, in full, the configuration labels of ``panel``
            to draw; its first group is the parameter value, e.g. ``r"cebp_T(.+)/paper-per_worker"``.
        references (sequence of str): ``"<panel>/<sampler>/<variant>"`` of each reference configuration, e.g.
            ``"push-standard/her/paper"``.
        epochs (sequence of int): the epoch counts (from 1) to draw a line each.
        out (str or Path): the PNG's path.
        metric (str, optional): the CSV column drawn. Defaults to ``"test_success"``.
        parameter_name (str, optional): the parameter's name on the x axis and in the legend. Defaults to
            ``"sigmoid temperature T"``.
        full_seeds (int, optional): the seeds a point needs to be drawn solid. Defaults to ``None``: the most seeds
            any point or reference drawn has.
        title (str, optional): the figure's title. Defaults to ``None``: the panel's task and the parameter.
        planned_values (sequence of float, optional): the values the study runs; the x axis spans and ticks them
            all, so that a value without runs yet is seen to be missing. Defaults to none (the values with runs).

    Returns:
        ``{n: {"parameter": {value: (iqm, low, high, seeds)}, "references": {reference: (iqm, low, high, seeds)}}}``
        per epoch count ``n``, as drawn (a reference without a seed at ``n`` is left out).

    Raises:
        ValueError: an epoch count below 1, a parameter value that is not a positive number, a pattern without a
            group, or no run of the parameter that has reached any of ``epochs``.
        KeyError: ``panel`` or a reference has no runs, or ``parameter_pattern`` matches no configuration.

    Examples:
        >>> import tempfile
        >>> with tempfile.TemporaryDirectory() as d:
        ...     for label, values in (("push-temperature/cebp_T0.1/paper", (0.2, 0.6)),
        ...                           ("push-temperature/cebp_T5/paper", (0.1, 0.4)),
        ...                           ("push-standard/her/paper", (0.2, 0.5))):
        ...         run = Path(d) / label / "seed0"
        ...         run.mkdir(parents=True)
        ...         rows = [f"{e},{v}" for e, v in enumerate(values)]
        ...         _ = (run / CSV_NAME).write_text("\\n".join(["epoch,test_success", *rows]) + "\\n")
        ...     drawn = plot_against_parameter(d, "push-temperature", r"cebp_T(.+)/paper", ["push-standard/her/paper"],
        ...                                    [2], Path(d) / "against.png")
        >>> drawn[2]["parameter"]
        {0.1: (0.6, 0.6, 0.6, 1), 5.0: (0.4, 0.4, 0.4, 1)}
        >>> drawn[2]["references"]
        {'push-standard/her/paper': (0.5, 0.5, 0.5, 1)}
    """
    if any(n < 1 for n in epochs):
        raise ValueError(f"epochs={list(epochs)}: epoch counts start at 1")
    by_value, reference_curves = parameter_runs(root, panel, parameter_pattern, references, metric)
    drawn: dict[int, dict[str, dict]] = {}
    for n in epochs:
        parameter = {value: seeds_summary(values) for value, (_, curves) in by_value.items()
                     if (values := values_at_epoch(curves, n))}
        reference_levels = {reference: seeds_summary(values) for reference, curves in reference_curves.items()
                            if (values := values_at_epoch(curves, n))}
        drawn[n] = {"parameter": parameter, "references": reference_levels}
    if not any(drawn[n]["parameter"] for n in drawn):
        raise ValueError(f"no run of {parameter_pattern!r} in {panel} has reached any of epochs={list(epochs)}")
    full = full_seeds if full_seeds is not None else max(
        seeds for summary in drawn.values() for kind in summary.values() for *_, seeds in kind.values()
    )
    palette = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    reference_style = {reference: REFERENCE_LINESTYLES[i % len(REFERENCE_LINESTYLES)]
                       for i, reference in enumerate(references)}
    caption_text = (
        f"Points: IQM of {metric.replace('_', ' ')} over the seeds named (n); hollow: fewer than {seed_count(full)};"
        " bars: 95% stratified-bootstrap CI. Lines: the reference methods' IQM, light bands their CI,"
        " in the colour of the epoch count."
    )
    fig, ax = plt.subplots(figsize=(7, 6.2))
    for i, (n, summary) in enumerate(drawn.items()):
        colour = palette[i % len(palette)]
        dodge = 10 ** (PARAMETER_DODGE * (i - (len(drawn) - 1) / 2))
        if summary["parameter"]:
            values = np.array(list(summary["parameter"]))
            mean, low, high, seeds = map(np.array, zip(*summary["parameter"].values()))
            x = values * dodge
            ax.plot(x, mean, color=colour, label=f"each {parameter_name.split()[-1]}, {epochs_phrase(n)}")
            ax.errorbar(x, mean, yerr=[mean - low, high - mean], fmt="none", ecolor=colour, capsize=4)
            for xi, yi, count in zip(x, mean, seeds):
                ax.plot(xi, yi, marker="o", markersize=8, color=colour, linestyle="none",
                        markerfacecolor=colour if count >= full else "white", markeredgewidth=1.5)
                ax.annotate(f"n={count}", (xi, yi), textcoords="offset points", xytext=(9, 2), fontsize=8,
                            color=colour)
        for reference, (level, low, high, seeds) in summary["references"].items():
            ax.axhline(level, color=colour, linestyle=reference_style[reference], linewidth=1.2,
                       label=f"{method_label(reference.partition('/')[2])} {epochs_phrase(n)} ({seed_count(seeds)})")
            ax.axhspan(low, high, color=colour, alpha=0.07)
    ax.set_xscale("log")
    ticks = sorted({*by_value, *planned_values})
    ax.set_xticks(ticks, [f"{value:g}" for value in ticks])
    ax.xaxis.set_minor_locator(NullLocator())
    ax.set_xlim(ticks[0] / 2, ticks[-1] * 2)
    ax.set_xlabel(f"{parameter_name} (log scale)")
    ax.set_ylabel(f"{metric.replace('_', ' ')} (IQM, 95% CI)")
    default_title = f"{panel_title(panel)}: against the {parameter_name}"
    ax.set_title(textwrap.fill(title if title is not None else default_title, 60))
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, 0), borderaxespad=4.5, ncol=2)
    fig.text(0.5, 0.01, "\n".join(textwrap.wrap(caption_text, 110)), ha="center", va="bottom", fontsize=8)
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return drawn


def iqm_cell(per_seed: list[float], seeds_in_total: int) -> str:
    """``IQM [95% CI]`` of the seeds' values, naming how many when not all seeds count.

    Args:
        per_seed (list of float): one value per seed that counts; none gives ``-``.
        seeds_in_total (int): the configuration's seeds.

    Examples:
        >>> iqm_cell([0.1, 0.3], 3)
        '0.20 [0.10, 0.30] (2 seeds)'
        >>> iqm_cell([], 3)
        '-'
    """
    if not per_seed:
        return "-"
    mean, low, high, seeds = seeds_summary(per_seed)
    count = f" ({seed_count(seeds)})" if seeds < seeds_in_total else ""
    return f"{mean:.2f} [{low:.2f}, {high:.2f}]{count}"


def improvement_cell(per_seed: list[float], baseline: list[float]) -> str:
    """``P(X > baseline) [95% CI]`` over the seeds' values, or ``-`` when either side has none.

    Args:
        per_seed (list of float): one value per seed of the configuration.
        baseline (list of float): one value per seed of the baseline.

    Examples:
        >>> improvement_cell([0.5, 0.6], [0.1, 0.2])
        '1.00 [1.00, 1.00]'
    """
    if not per_seed or not baseline:
        return "-"
    low, high = probability_of_improvement_ci(per_seed, baseline)
    return f"{probability_of_improvement(per_seed, baseline):.2f} [{low:.2f}, {high:.2f}]"


def epochs_phrase(n: int) -> str:
    """``"after 1 epoch"``, ``"after 10 epochs"``: the epoch a table column reads.

    Args:
        n (int): the epochs trained.

    Examples:
        >>> epochs_phrase(1), epochs_phrase(10)
        ('after 1 epoch', 'after 10 epochs')
    """
    return f"after {n} epoch{'s' * (n > 1)}"


def improvement_cells(curves: list[np.ndarray], baseline: list[np.ndarray] | None, at: Sequence[int]) -> list[str]:
    """:func:`improvement_cell` after each of ``at`` epochs: ``(baseline)`` in the baseline's own row (``curves`` is
    ``baseline``), ``-`` without a baseline (``None``).

    Args:
        curves (list of np.ndarray): one curve per seed of the row's configuration.
        baseline (list of np.ndarray or None): one curve per seed of the baseline configuration.
        at (sequence of int): the epoch counts (from 1) of the columns.

    Examples:
        >>> her = [np.array([0.1, 0.2])]
        >>> improvement_cells([np.array([0.3, 0.1])], her, [1, 2]), improvement_cells(her, her, [1, 2])
        (['1.00 [1.00, 1.00]', '0.00 [0.00, 0.00]'], ['(baseline)', '(baseline)'])
    """
    if curves is baseline:
        return ["(baseline)"] * len(at)
    return [improvement_cell(values_at_epoch(curves, n), values_at_epoch(baseline or [], n)) for n in at]


def hours_cell(epoch_seconds: list[np.ndarray]) -> str:
    """The training hours of a configuration's runs, the sum of their ``epoch_s``; ``-`` when none logs it.

    Args:
        epoch_seconds (list of np.ndarray): each seed's ``epoch_s`` curve.

    Examples:
        >>> hours_cell([np.array([1800.0, 1800.0]), np.array([3600.0])]), hours_cell([])
        ('2.0', '-')
    """
    if not epoch_seconds:
        return "-"
    return f"{sum(curve.sum() for curve in epoch_seconds) / 3600:.1f}"


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    """A Markdown table of ``rows`` under ``header``.

    Args:
        header (sequence of str): the column heads.
        rows (sequence of sequence of str): the rows' cells.

    Examples:
        >>> print(markdown_table(["method", "seeds"], [["HER", "3"]]))
        | method | seeds |
        |---|---|
        | HER | 3 |
    """
    return "\n".join(["| " + " | ".join(header) + " |", "|" + "---|" * len(header),
                      *("| " + " | ".join(cells) + " |" for cells in rows)])


def summary_table(
    root: str | Path,
    after_epochs: list[int],
    metric: str = "test_success",
    mean_over: tuple[int, int] | None = None,
    improvement_at: int | Sequence[int] = (),
    baseline: str = "her",
    panels: Sequence[str] | None = None,
    configurations: Sequence[str] | None = None,
) -> str:
    """A Markdown table: per task and configuration (its method, :func:`method_label`, and its run folder), the
    IQM [95% stratified-bootstrap CI] of ``metric`` after each of ``after_epochs`` epochs over the seeds that got
    there, and the runs' training hours (the sum of their ``epoch_s``). Every column head says what its cells are.

    Args:
        root (str or Path): the sweep folder (see :func:`collect_sweep`).
        after_epochs (list of int): the epoch counts (from 1) to give a column each.
        metric (str, optional): the CSV column summarised. Defaults to ``"test_success"``.
        mean_over (tuple of int, optional): ``(first, last)`` adds a column of each seed's mean over epochs
            ``first`` to ``last`` (counted from 1, both included; seeds that reached ``last``), steadier than one
            epoch's value while success is still a few test episodes. Defaults to ``None``.
        improvement_at (int or sequence of int, optional): per ``n``, a column of the probability that a
            configuration's run beats a run of the panel's ``baseline`` configuration after ``n`` epochs, with
            its 95% interval, over the seeds of either that reached epoch ``n``. Defaults to none.
        baseline (str, optional): the sampler folder compared with (``-`` in panels without it).
            Defaults to ``"her"``.
        panels (sequence of str, optional): keeps those task folders. Defaults to ``None`` (all, sorted).
        configurations (sequence of str, optional): keeps the configurations that match these shell patterns
            (:func:`select_configurations`). Defaults to ``None`` (all).

    Raises:
        ValueError: an epoch count below 1, or ``mean_over`` not ``1 <= first <= last``.
        FileNotFoundError: no run under ``root`` logs ``metric`` (or matches ``configurations``).

    Examples:
        >>> import tempfile
        >>> with tempfile.TemporaryDirectory() as d:
        ...     for sampler, runs in (("her", [(0.1, 0.5), (0.3, 0.7), (0.2,)]), ("cebp", [(0.2, 0.9), (0.4, 0.8)])):
        ...         for seed, values in enumerate(runs):
        ...             run = Path(d) / "push-extended" / sampler / "paper-per_worker" / f"seed{seed}"
        ...             run.mkdir(parents=True)
        ...             rows = [f"{e},{v},1800" for e, v in enumerate(values)]
        ...             _ = (run / CSV_NAME).write_text("\\n".join(["epoch,test_success,epoch_s", *rows]) + "\\n")
        ...     print(summary_table(d, [1, 2], improvement_at=2))
        | task | method | run folder | seeds | IQM [95% CI] after 1 epoch | IQM [95% CI] after 2 epochs | P(> HER) [95% CI] after 2 epochs | training hours |
        |---|---|---|---|---|---|---|---|
        | Push: extended goals | HER | her/paper-per_worker | 3 | 0.20 [0.10, 0.30] | 0.60 [0.50, 0.70] (2 seeds) | (baseline) | 2.5 |
        | Push: extended goals | CEBP (paper form) | cebp/paper-per_worker | 2 | 0.30 [0.20, 0.40] | 0.85 [0.80, 0.90] | 1.00 [1.00, 1.00] | 2.0 |
    """
    if any(n < 1 for n in after_epochs):
        raise ValueError(f"after_epochs={after_epochs}: epoch counts start at 1")
    if mean_over is not None and not 1 <= mean_over[0] <= mean_over[1]:
        raise ValueError(f"mean_over={tuple(mean_over)}: needs 1 <= first <= last")
    improvement_at = [improvement_at] if isinstance(improvement_at, int) else list(improvement_at)
    if any(n < 1 for n in improvement_at):
        raise ValueError(f"improvement_at={improvement_at}: epoch counts start at 1")
    root = Path(root)
    values = select_configurations(collect_sweep(root, metric), configurations)
    if not values:
        raise FileNotFoundError(f"no {CSV_NAME} under {root}")
    values = select_panels(values, panels, root)
    epoch_seconds = collect_sweep(root, "epoch_s")
    header = ["task", "method", "run folder", "seeds", *(f"IQM [95% CI] {epochs_phrase(n)}" for n in after_epochs)]
    if mean_over is not None:
        header.append(f"IQM [95% CI] of each seed's mean over epochs {mean_over[0]}-{mean_over[1]}")
    header.extend(f"P(> {sampler_name(baseline)}) [95% CI] {epochs_phrase(n)}" for n in improvement_at)
    header.append("training hours")
    rows = []
    for panel, curves_by_label in values.items():
        baselines = [curves for label, curves in curves_by_label.items() if sampler_of(label) == baseline]
        for label, curves in sorted(curves_by_label.items(), key=lambda item: method_order(item[0])):
            cells = [panel_title(panel), method_label(label), label, str(len(curves))]
            for n in after_epochs:
                cells.append(iqm_cell(values_at_epoch(curves, n), len(curves)))
            if mean_over is not None:
                first, last = mean_over
                window = [curve[first - 1 : last].mean() for curve in curves if len(curve) >= last]
                cells.append(iqm_cell(window, len(curves)))
            cells += improvement_cells(curves, baselines[0] if len(baselines) == 1 else None, improvement_at)
            cells.append(hours_cell(epoch_seconds[panel][label]))
            rows.append(cells)
    return markdown_table(header, rows)


def panel_tables(
    root: str | Path,
    after_epochs: list[int],
    metric: str = "test_success",
    mean_over: tuple[int, int] | None = None,
    improvement_at: Sequence[int] = (),
    baseline: str = "her",
    panels: Sequence[str] | None = None,
    configurations: Sequence[str] | None = None,
) -> str:
    """One :func:`summary_table` per panel (task folder), under a heading of its own, each with those of
    ``after_epochs`` and ``improvement_at`` that some run of the panel reached, and ``mean_over`` where one
    reached its last epoch: a task trained for 12 epochs gets no empty column for 20.

    Args:
        root (str or Path): the sweep folder (see :func:`collect_sweep`).
        after_epochs (list of int): as :func:`summary_table`'s.
        metric (str, optional): the CSV column summarised. Defaults to ``"test_success"``.
        mean_over (tuple of int, optional): as :func:`summary_table`'s. Defaults to ``None``.
        improvement_at (sequence of int, optional): as :func:`summary_table`'s. Defaults to none.
        baseline (str, optional): as :func:`summary_table`'s. Defaults to ``"her"``.
        panels (sequence of str, optional): keeps those task folders, in that order. Defaults to ``None``
            (all, sorted).
        configurations (sequence of str, optional): keeps the configurations that match these shell patterns.
            Defaults to ``None`` (all).

    Examples:
        >>> import tempfile
        >>> with tempfile.TemporaryDirectory() as d:
        ...     for task, epochs in (("push-standard", 2), ("slide-standard", 3)):
        ...         run = Path(d) / task / "her" / "paper" / "seed0"
        ...         run.mkdir(parents=True)
        ...         rows = [f"{e},0.5,60" for e in range(epochs)]
        ...         _ = (run / CSV_NAME).write_text("\\n".join(["epoch,test_success,epoch_s", *rows]) + "\\n")
        ...     print(panel_tables(d, [2, 3]))
        ### Push: standard goals (push-standard)
        <BLANKLINE>
        | task | method | run folder | seeds | IQM [95% CI] after 2 epochs | training hours |
        |---|---|---|---|---|---|
        | Push: standard goals | HER | her/paper | 1 | 0.50 [0.50, 0.50] | 0.0 |
        <BLANKLINE>
        ### Slide: standard goals (slide-standard)
        <BLANKLINE>
        | task | method | run folder | seeds | IQM [95% CI] after 2 epochs | IQM [95% CI] after 3 epochs | training hours |
        |---|---|---|---|---|---|---|
        | Slide: standard goals | HER | her/paper | 1 | 0.50 [0.50, 0.50] | 0.50 [0.50, 0.50] | 0.1 |
    """
    curves = select_panels(select_configurations(collect_sweep(Path(root), metric), configurations), panels, Path(root))
    sections = []
    for panel, curves_by_label in curves.items():
        longest = max(len(curve) for seeds in curves_by_label.values() for curve in seeds)
        table = summary_table(
            root, [n for n in after_epochs if n <= longest], metric,
            mean_over=mean_over if mean_over is not None and mean_over[1] <= longest else None,
            improvement_at=[n for n in improvement_at if n <= longest], baseline=baseline, panels=[panel],
            configurations=configurations,
        )
        sections.append(f"### {panel_title(panel)} ({panel})\n\n{table}")
    return "\n\n".join(sections)


def parameter_table(
    root: str | Path,
    panel: str,
    parameter_pattern: str,
    references: Sequence[str],
    after_epochs: Sequence[int],
    metric: str = "test_success",
    improvement_at: Sequence[int] = (),
    parameter_baseline: float | None = None,
    parameter_name: str = "sigmoid temperature T",
    planned_values: Sequence[float] = (),
) -> str:
    """A Markdown table of a parameter study (the runs :func:`plot_against_parameter` draws): one row per parameter
    value, ascending, then one per reference configuration, in the order given. Each row gives the method
    (:func:`method_label`), the run folder ``<panel>/<sampler>/<variant>``, the seeds, the IQM [95% CI] of
    ``metric`` after each of ``after_epochs`` epochs, the probability of improvement over ``parameter_baseline``'s
    runs and over the first reference's after each of ``improvement_at`` epochs (as :func:`summary_table`'s), and
    the training hours. A planned value without runs yet has a row of ``-``, its seeds ``(not run yet)``.

    Args:
        root (str or Path): the sweep folder (see :func:`collect_sweep`).
        panel (str): the task folder of the parameter's runs.
        parameter_pattern (str): as :func:`plot_against_parameter`'s.
        references (sequence of str): ``"<panel>/<sampler>/<variant>"`` of each reference configuration.
        after_epochs (sequence of int): the epoch counts (from 1) to give an IQM column each.
        metric (str, optional): the CSV column summarised. Defaults to ``"test_success"``.
        improvement_at (sequence of int, optional): the epoch counts of the probability-of-improvement columns.
            Defaults to none.
        parameter_baseline (float, optional): the parameter value whose runs the first probability columns compare
            with. Defaults to ``None`` (no such columns).
        parameter_name (str, optional): the parameter's name; its last word names ``parameter_baseline`` in the
            column heads (``P(> T = 0.01)``). Defaults to ``"sigmoid temperature T"``.
        planned_values (sequence of float, optional): the values the study runs, each given a row. Defaults to none
            (the values with runs).

    Raises:
        ValueError: an epoch count below 1, a ``parameter_baseline`` that is neither a value with runs nor a planned
            one, ``parameter_baseline`` without ``improvement_at``, or ``improvement_at`` with nothing to compare
            with; and as :func:`parameter_runs`.
        KeyError: as :func:`parameter_runs`.

    Examples:
        >>> import tempfile
        >>> with tempfile.TemporaryDirectory() as d:
        ...     for label, values in (("push-temperature/cebp_T0.01/paper-per_worker", (0.2, 0.6)),
        ...                           ("push-temperature/cebp_T5/paper-per_worker", (0.1, 0.4)),
        ...                           ("push-standard/her/paper", (0.2, 0.5))):
        ...         run = Path(d) / label / "seed0"
        ...         run.mkdir(parents=True)
        ...         rows = [f"{e},{v},1800" for e, v in enumerate(values)]
        ...         _ = (run / CSV_NAME).write_text("\\n".join(["epoch,test_success,epoch_s", *rows]) + "\\n")
        ...     table = parameter_table(d, "push-temperature", r"cebp_T(.+)/paper-per_worker",
        ...                             ["push-standard/her/paper"], [2], improvement_at=[2], parameter_baseline=0.01,
        ...                             planned_values=[0.01, 1, 5])
        >>> print(table)
        | method | run folder | seeds | IQM [95% CI] after 2 epochs | P(> T = 0.01) [95% CI] after 2 epochs | P(> HER) [95% CI] after 2 epochs | training hours |
        |---|---|---|---|---|---|---|
        | CEBP (paper form), T = 0.01 | push-temperature/cebp_T0.01/paper-per_worker | 1 | 0.60 [0.60, 0.60] | (baseline) | 1.00 [1.00, 1.00] | 1.0 |
        | CEBP (paper form), T = 1 | - | (not run yet) | - | - | - | - |
        | CEBP (paper form), T = 5 | push-temperature/cebp_T5/paper-per_worker | 1 | 0.40 [0.40, 0.40] | 0.00 [0.00, 0.00] | 0.00 [0.00, 0.00] | 1.0 |
        | HER | push-standard/her/paper | 1 | 0.50 [0.50, 0.50] | 0.00 [0.00, 0.00] | (baseline) | 1.0 |
    """
    if any(n < 1 for n in [*after_epochs, *improvement_at]):
        raise ValueError(f"after_epochs={list(after_epochs)}, improvement_at={list(improvement_at)}: epoch counts"
                         " start at 1")
    by_value, reference_curves = parameter_runs(root, panel, parameter_pattern, references, metric)
    values = sorted({*by_value, *planned_values})
    if parameter_baseline is not None and parameter_baseline not in values:
        raise ValueError(f"parameter_baseline={parameter_baseline:g} is not a value of the study; its values (with"
                         f" runs or planned): {[f'{value:g}' for value in values]}")
    if parameter_baseline is not None and not improvement_at:
        raise ValueError(f"parameter_baseline={parameter_baseline:g} needs improvement_at: the epochs at which the"
                         " runs are compared with it")
    if improvement_at and parameter_baseline is None and not references:
        raise ValueError(f"improvement_at={list(improvement_at)} needs a parameter_baseline or a reference to compare"
                         " with")
    symbol = parameter_name.split()[-1]
    # A planned value's method is named as its runs' folder will be: a run's label with the value in the group.
    some_label = next(iter(by_value.values()))[0]
    group = re.compile(parameter_pattern).fullmatch(some_label).span(1)
    epoch_seconds = collect_sweep(Path(root), "epoch_s")
    # Per row: (method, run folder or None without runs, one curve per seed, the curves of epoch_s).
    row_of: dict[float | str, tuple[str, str | None, list[np.ndarray], list[np.ndarray]]] = {}
    for value in values:
        if value in by_value:
            label, curves = by_value[value]
            row_of[value] = (method_label(label), f"{panel}/{label}", curves, epoch_seconds[panel][label])
        else:
            planned = f"{some_label[:group[0]]}{value:g}{some_label[group[1]:]}"
            row_of[value] = (method_label(planned), None, [], [])
    for reference, curves in reference_curves.items():
        reference_panel, _, label = reference.partition("/")
        row_of[reference] = (method_label(label), reference, curves, epoch_seconds[reference_panel][label])
    baselines = {}  # the name each column head gives it: its curves
    if parameter_baseline is not None:
        baselines[f"{symbol} = {parameter_baseline:g}"] = row_of[parameter_baseline][2]
    if references:
        baselines[method_label(references[0].partition("/")[2])] = reference_curves[references[0]]

    header = ["method", "run folder", "seeds", *(f"IQM [95% CI] {epochs_phrase(n)}" for n in after_epochs)]
    header += [f"P(> {name}) [95% CI] {epochs_phrase(n)}" for name in baselines for n in improvement_at]
    header.append("training hours")
    rows = []
    for method, folder, curves, seconds in row_of.values():
        cells = [method, folder or "-", str(len(curves)) if folder else "(not run yet)"]
        cells += [iqm_cell(values_at_epoch(curves, n), len(curves)) for n in after_epochs]
        for baseline in baselines.values():
            cells += improvement_cells(curves, baseline, improvement_at)
        cells.append(hours_cell(seconds))
        rows.append(cells)
    return markdown_table(header, rows)


def main(argv: list[str] | None = None) -> None:
    """The command line: draws the sweep (:func:`plot_sweep`) and, with ``--table``, prints its tables; with
    ``--against``, draws a parameter study (:func:`plot_against_parameter`) and, with ``--table``, prints its table
    (:func:`parameter_table`).

    Args:
        argv (list of str, optional): the arguments (``--help`` lists them). Defaults to ``None``: the
            process's own.

    Examples:
        >>> import contextlib, io, tempfile
        >>> with tempfile.TemporaryDirectory() as d:
        ...     run = Path(d) / "push-standard" / "her" / "paper" / "seed0"
        ...     run.mkdir(parents=True)
        ...     _ = (run / CSV_NAME).write_text("epoch,test_success,epoch_s\\n0,0.1,60\\n1,0.4,60\\n")
        ...     printed = io.StringIO()
        ...     with contextlib.redirect_stdout(printed):
        ...         main([d, "--table", "2"])
        ...     printed.getvalue().splitlines()[-1]
        '| Push: standard goals | HER | her/paper | 1 | 0.40 [0.40, 0.40] | 0.0 |'
    """
    parser = argparse.ArgumentParser(
        description="Success curves of a sweep (IQM over seeds, 95% stratified-bootstrap band), and tables."
    )
    parser.add_argument("--version", action="version", version=f"torchrl-cebp {torchrl_cebp.__version__}")
    parser.add_argument("root", nargs="?", default="runs",
                        help="sweep folder, e.g. multirun/... (default: %(default)s, where training writes its runs)")
    parser.add_argument("--out", help="PNG path (default: <root>/<metric>.png)")
    parser.add_argument("--metric", default="test_success", help="CSV column to plot")
    parser.add_argument("--title", help="figure title (default: each panel is titled with its task)")
    parser.add_argument("--log-y", action="store_true", help="a log scale for a metric that spans decades")
    parser.add_argument("--panels", nargs="+", metavar="TASK_FOLDER", help="draw these task folders only, in this order")
    parser.add_argument(
        "--configurations", nargs="+", metavar="PATTERN",
        help="keep the configurations <sampler>/<variant> that match one of these shell patterns (e.g. 'her/*')",
    )
    parser.add_argument(
        "--reference", metavar="CSV", help="published values to mark (columns panel,sampler,name,epoch,value)"
    )
    parser.add_argument(
        "--reference-panel", metavar="TASK_FOLDER", help="with --reference: mark every panel with this panel's values"
    )
    parser.add_argument(
        "--table", nargs="+", type=int, metavar="N",
        help="also print a Markdown table of the metric after N epochs (with --against: a row per parameter value,"
             " planned ones included, then per reference)",
    )
    parser.add_argument(
        "--mean-over", nargs=2, type=int, metavar=("FIRST", "LAST"),
        help="with --table: a column of each seed's mean over epochs FIRST to LAST",
    )
    parser.add_argument(
        "--improvement-at", nargs="+", type=int, default=[], metavar="N",
        help="with --table: a column of the probability of improvement over --baseline after each N epochs (with"
             " --against: over --parameter-baseline, then over the first --against-references)",
    )
    parser.add_argument(
        "--baseline", help="the sampler folder --improvement-at compares with (default: her; not with --against)"
    )
    parser.add_argument(
        "--tables-out", metavar="MD",
        help="with --table: also write one table per task to this Markdown file, each with the epochs its runs reached",
    )
    parser.add_argument(
        "--against", metavar="REGEX",
        help="instead of curves: the metric after --at epochs against the parameter that the first group of REGEX"
             " reads from the configurations of the one --panels folder, on a log axis",
    )
    parser.add_argument("--at", nargs="+", type=int, default=[], metavar="N", help="with --against: the epoch counts")
    parser.add_argument(
        "--against-references", nargs="+", default=[], metavar="PANEL/SAMPLER/VARIANT",
        help="with --against: configurations drawn as horizontal reference lines, and the table's last rows (the first"
             " is the second baseline of --improvement-at)",
    )
    parser.add_argument(
        "--parameter-name", default="sigmoid temperature T",
        help="with --against: the x axis's name; its last word names --parameter-baseline in the table",
    )
    parser.add_argument(
        "--parameter-values", nargs="+", type=float, default=[], metavar="VALUE",
        help="with --against: the values the study runs, ticked on the x axis and given a table row whether they"
             " have runs yet or not",
    )
    parser.add_argument(
        "--parameter-baseline", type=float, metavar="VALUE",
        help="with --against and --improvement-at: the parameter value whose runs the first probability columns"
             " compare with",
    )
    args = parser.parse_args(argv)
    for option, value in (
        ("--mean-over", args.mean_over), ("--improvement-at", args.improvement_at), ("--tables-out", args.tables_out)
    ):
        if value and not args.table:
            parser.error(f"{option} goes with --table: give --table too")
    if args.parameter_baseline is not None and not args.improvement_at:
        parser.error("--parameter-baseline goes with --improvement-at: give --improvement-at too")
    if args.against:
        if not args.at or args.panels is None or len(args.panels) != 1:
            parser.error("--against needs --at and exactly one --panels folder")
        for option, value, why in (
            ("--reference", args.reference, "the pattern picks the configurations drawn"),
            ("--reference-panel", args.reference_panel, "the pattern picks the configurations drawn"),
            ("--configurations", args.configurations, "the pattern picks the configurations drawn"),
            ("--log-y", args.log_y, "the pattern picks the configurations drawn"),
            ("--baseline", args.baseline, "give --parameter-baseline, and the first --against-references"),
            ("--mean-over", args.mean_over, "its table has the --table and --improvement-at columns"),
            ("--tables-out", args.tables_out, "its one table is printed"),
        ):
            if value:
                parser.error(f"{option} does not go with --against: {why}")
        out = args.out or Path(args.root) / f"{args.metric}_against_parameter.png"
        drawn = plot_against_parameter(args.root, args.panels[0], args.against, args.against_references, args.at,
                                       out, args.metric, args.parameter_name, title=args.title,
                                       planned_values=args.parameter_values)
        print(f"wrote {out}")
        if args.table:
            print(parameter_table(args.root, args.panels[0], args.against, args.against_references, args.table,
                                  args.metric, args.improvement_at, args.parameter_baseline, args.parameter_name,
                                  args.parameter_values))
            return
        for n, summary in drawn.items():  # the drawn points, where no table gives them
            for value, (level, low, high, seeds) in summary["parameter"].items():
                print(f"{epochs_phrase(n)}: {args.parameter_name} = {value:g}: {level:.2f} [{low:.2f}, {high:.2f}]"
                      f" ({seed_count(seeds)})")
            for reference, (level, low, high, seeds) in summary["references"].items():
                print(f"{epochs_phrase(n)}: {reference}: {level:.2f} [{low:.2f}, {high:.2f}] ({seed_count(seeds)})")
        return
    for option, value in (
        ("--at", args.at), ("--against-references", args.against_references),
        ("--parameter-values", args.parameter_values), ("--parameter-baseline", args.parameter_baseline is not None),
    ):
        if value:
            parser.error(f"{option} goes with --against: give --against too")
    if args.reference_panel and not args.reference:
        parser.error("--reference-panel goes with --reference: give --reference too")
    out = plot_sweep(args.root, args.out, args.metric, args.title, args.log_y, args.panels, args.reference,
                     args.configurations, args.reference_panel)
    print(f"wrote {out}")
    if args.table:
        # The figure has refused any panel without runs that the reference does not name; those left have no rows.
        with_runs = select_configurations(collect_sweep(Path(args.root), args.metric), args.configurations)
        panels = None if args.panels is None else [panel for panel in args.panels if panel in with_runs]
        baseline = args.baseline or "her"
        print(summary_table(args.root, args.table, args.metric, args.mean_over, args.improvement_at, baseline,
                            panels, args.configurations))
        if args.tables_out:
            tables = panel_tables(
                args.root, args.table, args.metric, args.mean_over, args.improvement_at, baseline, panels,
                args.configurations,
            )
            Path(args.tables_out).write_text(tables + "\n")
            print(f"wrote {args.tables_out}")


if __name__ == "__main__":
    main()
