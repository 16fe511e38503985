"""The plot command draws a PNG from the runs of a sweep."""
import matplotlib.pyplot as plt
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from torchrl_cebp.plot import (
    SAMPLER_NAMES,
    collect_sweep,
    draw_sweep,
    iqm_band,
    main,
    method_label,
    parameter_table,
    plot_against_parameter,
    select_configurations,
    summary_table,
)

COMMITTED_RUNS = Path(__file__).parents[1] / "docs" / "results" / "comparison"


def write_run(folder, success):
    folder.mkdir(parents=True)
    lines = ["epoch,test_success,loss_actor,epoch_s"] + [f"{e},{s},0.1,60" for e, s in enumerate(success)]
    (folder / "progress.csv").write_text("\n".join(lines) + "\n")


def legend(ax):
    """``{legend label, its wrapped lines joined: line}`` of a panel's curves and markers."""
    return {line.get_label().replace("\n", " "): line for line in ax.get_lines() if not line.get_label().startswith("_")}


def table_rows(out):
    """``{run folder: cells}`` of the Markdown table rows printed in ``out``."""
    rows = [line.split(" | ") for line in out.splitlines() if line.startswith("| ") and not line.startswith("| task")]
    return {cells[2]: cells for cells in rows}


def test_plot_groups_seeds_and_draws_a_png(tmp_path, capsys):
    write_run(tmp_path / "push-standard/her/default/seed0", [0.0, 0.1, 0.2])
    write_run(tmp_path / "push-standard/her/default/seed1", [0.0, 0.3, 0.4])
    write_run(tmp_path / "push-standard/cebp/default/seed0", [0.1, 0.5])
    groups = collect_sweep(tmp_path, "test_success")
    assert set(groups) == {"push-standard"}
    assert sorted(groups["push-standard"]) == ["cebp/default", "her/default"]
    assert len(groups["push-standard"]["her/default"]) == 2
    main([str(tmp_path)])
    png = tmp_path / "test_success.png"
    assert "wrote" in capsys.readouterr().out
    image = np.asarray(Image.open(png).convert("RGB"))
    assert image.shape[0] > 100 and image.std() > 10  # a real figure, not a blank canvas


def test_a_run_of_one_epoch_is_drawn_as_a_point_and_longer_ones_as_lines(tmp_path):
    write_run(tmp_path / "sweep/push-standard/her/quick/seed0", [0.0])  # a line through one point draws nothing
    write_run(tmp_path / "sweep/push-standard/cebp/quick/seed0", [0.0, 0.1])
    (ax,) = draw_sweep(tmp_path / "sweep").axes
    markers = {label.split(",")[0]: line.get_marker() for label, line in legend(ax).items()}
    assert markers == {"HER": "o", "CEBP (paper form)": "None"}


def test_title_replaces_a_single_panels_folder_name_and_tops_several(tmp_path):
    write_run(tmp_path / "learning/her/seed0", [0.0, 0.1])
    assert [ax.get_title() for ax in draw_sweep(tmp_path / "learning").axes] == ["learning"]
    assert [ax.get_title() for ax in draw_sweep(tmp_path / "learning", title="FetchPush").axes] == ["FetchPush"]
    long_title = "Push on the released code's robot: joint control, extended goals, table-blind pads"
    (ax,) = draw_sweep(tmp_path / "learning", title=long_title, log_y=True).axes
    assert "\n" in ax.get_title() and ax.get_title().replace("\n", " ") == long_title  # wrapped, not cut off
    assert ax.get_yscale() == "log"
    write_run(tmp_path / "sweep/push-extended/her/paper/seed0", [0.0, 0.1])
    write_run(tmp_path / "sweep/slide-extended/her/paper/seed0", [0.0, 0.1])
    fig = draw_sweep(tmp_path / "sweep", title="all tasks")
    assert [ax.get_title() for ax in fig.axes] == ["Push: extended goals", "Slide: extended goals"]
    assert fig.get_suptitle() == "all tasks"


def test_one_task_folder_as_root_is_one_panel_of_its_samplers(tmp_path, capsys):
    for seed, (her, cebp) in enumerate([(0.1, 0.3), (0.2, 0.3)]):
        write_run(tmp_path / f"push-extended/her/paper/seed{seed}", [her])
        write_run(tmp_path / f"push-extended/cebp/paper/seed{seed}", [cebp])
    groups = collect_sweep(tmp_path / "push-extended", "test_success")
    assert {panel: sorted(labels) for panel, labels in groups.items()} == {"push-extended": ["cebp/paper", "her/paper"]}
    main([str(tmp_path / "push-extended"), "--table", "1", "--improvement-at", "1"])
    rows = table_rows(capsys.readouterr().out)
    assert list(rows) == ["her/paper", "cebp/paper"]  # HER first
    assert rows["cebp/paper"][0] == "| Push: extended goals"
    assert rows["cebp/paper"][5] == "1.00 [1.00, 1.00]"  # every cebp seed above every her seed
    write_run(tmp_path / "learning/collectors/her/seed0", [0.2])  # not the trainer's layout: one panel
    write_run(tmp_path / "learning/cebp/seed0", [0.4])
    assert {panel: sorted(labels) for panel, labels in collect_sweep(tmp_path / "learning", "test_success").items()} == {
        "learning": ["cebp", "collectors/her"]
    }


def test_a_sampler_keeps_its_colour_and_fractions_share_one_scale(tmp_path):
    write_run(tmp_path / "pick_place-extended/her/paper/seed0", [0.0, 0.01])
    write_run(tmp_path / "push-extended/cebp/paper/seed0", [0.1, 0.8])
    write_run(tmp_path / "push-extended/her/paper/seed0", [0.2, 0.9])
    pick_place, push = draw_sweep(tmp_path).axes
    her_alone, (her, cebp) = pick_place.get_lines(), push.get_lines()
    assert her_alone[0].get_color() == her.get_color() != cebp.get_color()
    assert pick_place.get_ylim() == push.get_ylim() and pick_place.get_ylim()[1] > 0.8
    unbounded = draw_sweep(tmp_path, metric="epoch_s").axes  # seconds: each task keeps its own scale
    assert not unbounded[0].get_shared_y_axes().joined(*unbounded)


def test_a_sampler_keeps_its_colour_across_variants_and_panels_and_its_variants_differ_in_style(tmp_path):
    write_run(tmp_path / "push-standard/her/paper/seed0", [0.1, 0.2])
    write_run(tmp_path / "push-standard/cebp_initial/paper/seed0", [0.0, 0.1])
    write_run(tmp_path / "push-standard/cebp_initial/paper-per_worker/seed0", [0.0, 0.3])
    write_run(tmp_path / "slide-standard-T70/her/paper-per_worker/seed0", [0.0, 0.1])
    reference = tmp_path / "paper.csv"
    reference.write_text("panel,sampler,name,epoch,value\nslide-standard-T70,her,HER (paper),2,0.47\n"
                         "slide-standard-T70,cper,CPER (paper),2,0.52\n")  # a sampler with no runs
    push, slide = draw_sweep(tmp_path, reference=reference).axes
    lines, slide_lines = legend(push), legend(slide)
    her_colour = lines["HER (1 seed)"].get_color()
    slide_her = slide_lines["HER (1 seed)"]
    assert slide_her.get_color() == slide_lines["HER (paper)"].get_color() == her_colour
    merged = lines["CEBP (Initial commit), merged buffer (superseded) (1 seed)"]
    per_worker = lines["CEBP (Initial commit) (1 seed)"]
    assert per_worker.get_linestyle() == "-"  # the method as the comparison runs it is solid
    assert merged.get_color() == per_worker.get_color() != her_colour
    assert merged.get_linestyle() != per_worker.get_linestyle()
    cper = slide_lines["CPER (paper)"].get_color()
    assert cper not in (her_colour, merged.get_color(), "grey")


def test_tables_out_writes_one_table_per_task_with_the_epochs_its_runs_reached(tmp_path, capsys):
    for seed in range(2):
        write_run(tmp_path / f"push-standard/her/paper/seed{seed}", [0.1, 0.2])
        write_run(tmp_path / f"push-standard/cebp/paper/seed{seed}", [0.2, 0.4])
        write_run(tmp_path / f"slide-standard-T70/her/paper/seed{seed}", [0.0, 0.1, 0.2])
    tables = tmp_path / "tables.md"
    main([str(tmp_path), "--out", str(tmp_path / "fig.png"), "--table", "2", "3", "--improvement-at", "2", "3",
          "--mean-over", "1", "3", "--tables-out", str(tables)])
    push, slide = tables.read_text().split("### ")[1:]
    assert push.startswith("Push: standard goals (push-standard)")
    assert slide.startswith("Slide: standard goals, 70-step episodes (slide-standard-T70)")
    assert "after 3 epochs" not in push and "P(> HER) [95% CI] after 2 epochs" in push
    assert "| cebp/paper | 2 | 0.40 [0.40, 0.40] | 1.00 [1.00, 1.00] |" in push
    assert "after 3 epochs" in slide and "P(> HER) [95% CI] after 3 epochs" in slide
    assert "mean over epochs 1-3" in slide and "mean over" not in push
    with pytest.raises(SystemExit):
        main([str(tmp_path), "--tables-out", str(tables)])
    assert "--tables-out goes with --table" in capsys.readouterr().err


def test_iqm_band_over_the_seeds_that_reached_each_epoch():
    mean, low, high, seeds = iqm_band([np.array([0.0, 0.2, 0.3]), np.array([0.4, 0.6]), np.array([0.8, 1.0])])
    np.testing.assert_allclose(mean, [0.4, 0.6, 0.3])  # three seeds: the IQM trims none
    np.testing.assert_allclose(low, [0.0, 0.2, 0.3])  # each extreme resample has probability 1/27 > 2.5%
    np.testing.assert_allclose(high, [0.8, 1.0, 0.3])
    assert seeds.tolist() == [3, 3, 1]


def test_legend_names_the_seeds_behind_each_stretch_of_a_curve(tmp_path):
    write_run(tmp_path / "push-standard/her/paper/seed0", [0.0, 0.1, 0.2, 0.5])
    write_run(tmp_path / "push-standard/her/paper/seed1", [0.0, 0.3])
    (ax,) = draw_sweep(tmp_path).axes
    assert [text.get_text() for text in ax.get_legend().get_texts()] == ["HER (2 seeds to epoch 2, 1 seed to 4)"]


def test_errors_name_the_problem(tmp_path):
    with pytest.raises(FileNotFoundError, match="no progress.csv"):
        main([str(tmp_path)])
    write_run(tmp_path / "a/b/seed0", [0.1])
    with pytest.raises(KeyError, match="'success'.*test_success"):
        main([str(tmp_path), "--metric", "success"])


def test_a_metric_some_samplers_do_not_log_draws_those_that_do(tmp_path):
    write_run(tmp_path / "push-extended/her/paper/seed0", [0.1, 0.2])  # uniform HER: no IS weights
    cebp = tmp_path / "push-extended/cebp/paper/seed0"
    cebp.mkdir(parents=True)
    (cebp / "progress.csv").write_text("epoch,test_success,is_weight_mean,epoch_s\n0,0.1,0.5,60\n1,0.3,0.25,60\n")
    groups = collect_sweep(tmp_path, "is_weight_mean")
    assert {label: [c.tolist() for c in curves] for label, curves in groups["push-extended"].items()} == {
        "cebp/paper": [[0.5, 0.25]]
    }
    (ax,) = draw_sweep(tmp_path, metric="is_weight_mean").axes
    assert [text.get_text().replace("\n", " ") for text in ax.get_legend().get_texts()] == [
        "CEBP (paper form), merged buffer (superseded) (1 seed)"
    ]


def test_table_gives_iqm_and_bootstrap_interval_after_n_epochs(tmp_path, capsys):
    for seed, success in enumerate([[0.0, 0.2], [0.0, 0.4], [0.0, 0.6]]):
        write_run(tmp_path / f"push-extended/cebp/paper-per_worker/seed{seed}", success)
    write_run(tmp_path / "push-extended/her/paper/seed0", [0.1])
    main([str(tmp_path), "--table", "1", "2"])
    lines = [line for line in capsys.readouterr().out.splitlines() if line.startswith("| ")]
    assert lines == [
        "| task | method | run folder | seeds | IQM [95% CI] after 1 epoch | IQM [95% CI] after 2 epochs | training hours |",
        "| Push: extended goals | HER | her/paper | 1 | 0.10 [0.10, 0.10] | - | 0.0 |",
        "| Push: extended goals | CEBP (paper form) | cebp/paper-per_worker | 3 | 0.00 [0.00, 0.00] | 0.40 [0.20, 0.60] | 0.1 |",
    ]
    with pytest.raises(ValueError, match="start at 1"):
        main([str(tmp_path), "--table", "0"])


def test_table_mean_over_a_window_of_epochs(tmp_path, capsys):
    for seed, success in enumerate([[0.0, 0.2, 0.4], [0.0, 0.4, 0.8], [0.2, 0.6]]):
        write_run(tmp_path / f"push-extended/cebp/paper/seed{seed}", success)
    main([str(tmp_path), "--table", "3", "--mean-over", "2", "3"])
    out = capsys.readouterr().out
    assert ("| task | method | run folder | seeds | IQM [95% CI] after 3 epochs"
            " | IQM [95% CI] of each seed's mean over epochs 2-3 | training hours |") in out
    # seeds 0 and 1 reached epoch 3: their means over epochs 2-3 are 0.3 and 0.6
    assert "| cebp/paper | 3 | 0.60 [0.40, 0.80] (2 seeds) | 0.45 [0.30, 0.60] (2 seeds) | 0.1 |" in out
    with pytest.raises(ValueError, match=r"mean_over=\(3, 2\)"):
        main([str(tmp_path), "--table", "3", "--mean-over", "3", "2"])
    with pytest.raises(SystemExit):
        main([str(tmp_path), "--mean-over", "2", "3"])
    assert "give --table too" in capsys.readouterr().err


def test_table_probability_of_improvement_over_her(tmp_path, capsys):
    for seed, (her, cebp) in enumerate([(0.1, 0.3), (0.2, 0.3), (0.4, 0.5)]):
        write_run(tmp_path / f"push-extended/her/paper/seed{seed}", [0.0, her])
        write_run(tmp_path / f"push-extended/cebp/paper/seed{seed}", [0.0, cebp])
    main([str(tmp_path), "--table", "2", "--improvement-at", "2"])
    rows = table_rows(capsys.readouterr().out)
    # cebp beats her in (3 + 3 + 1) of 9 pairs, ties none: 7/9
    assert rows["cebp/paper"][5].startswith("0.78 [")
    assert rows["her/paper"][5] == "(baseline)"
    with pytest.raises(SystemExit):
        main([str(tmp_path), "--improvement-at", "2"])


def test_table_probability_of_improvement_at_several_epochs(tmp_path, capsys):
    # her leads after 1 epoch in every pair, cebp after 2 in all but one tie: one column per epoch asked for
    for seed, (her, cebp) in enumerate([((0.2, 0.1), (0.1, 0.3)), ((0.3, 0.2), (0.0, 0.2)), ((0.4, 0.4), (0.1,))]):
        write_run(tmp_path / f"push-extended/her/paper/seed{seed}", her)
        write_run(tmp_path / f"push-extended/cebp/paper/seed{seed}", cebp)
    main([str(tmp_path), "--table", "2", "--improvement-at", "1", "2"])
    out = capsys.readouterr().out
    assert ("| IQM [95% CI] after 2 epochs | P(> HER) [95% CI] after 1 epoch | P(> HER) [95% CI] after 2 epochs"
            " | training hours |") in out
    rows = table_rows(out)
    # after 2 epochs cebp has seeds 0-1 (0.3, 0.2) against her's three (0.1, 0.2, 0.4): (2 + 1.5) / 6
    assert rows["cebp/paper"][5].startswith("0.00 [") and rows["cebp/paper"][6].startswith("0.58 [")
    assert rows["her/paper"][5:7] == ["(baseline)", "(baseline)"]
    with pytest.raises(ValueError, match="epoch counts start at 1"):
        main([str(tmp_path), "--table", "2", "--improvement-at", "0", "2"])


def test_panels_pick_and_order_the_tasks_and_published_values_are_marked_in_their_samplers_colour(tmp_path):
    for task in ("push-standard", "pick_place-standard", "push-extended"):
        write_run(tmp_path / f"{task}/her/paper/seed0", [0.1, 0.2])
        write_run(tmp_path / f"{task}/cebp_initial/paper/seed0", [0.0, 0.1])
    reference = tmp_path / "paper.csv"
    reference.write_text("panel,sampler,name,epoch,value\n"
                         "push-standard,her,HER (paper),10,0.5\npush-standard,her,HER (paper),18,0.97\n"
                         "push-standard,cebp_initial,C-Energy (paper),10,0.8\n")
    fig = draw_sweep(tmp_path, panels=["push-standard", "pick_place-standard"], reference=reference)
    push, pick_place = fig.axes
    assert [push.get_title(), pick_place.get_title()] == ["Push: standard goals", "PickAndPlace: standard goals"]
    lines = legend(push)
    # our runs end at epoch 2: the axis ends there, and the published values past it are noted, not drawn
    assert "HER (paper)" not in lines and push.get_xlim() == (0, 2.5)
    assert [text.get_text() for text in push.texts] == [
        "Past this axis:\nC-Energy (paper) 0.80 at epoch 10\nHER (paper) 0.50 at epoch 10\nHER (paper) 0.97 at epoch 18"
    ]
    write_run(tmp_path / "push-standard/her/paper/seed1", [0.1] * 12)
    (push,) = draw_sweep(tmp_path, panels=["push-standard"], reference=reference).axes
    lines = legend(push)
    assert lines["HER (paper)"].get_xydata().tolist() == [[10, 0.5]]
    assert [text.get_text() for text in push.texts] == ["Past this axis:\nHER (paper) 0.97 at epoch 18"]
    assert lines["HER (paper)"].get_color() == lines["HER (2 seeds to epoch 2, 1 seed to 12)"].get_color()
    assert lines["C-Energy (paper)"].get_color() == lines["CEBP (Initial commit), merged buffer (superseded) (1 seed)"].get_color()
    assert lines["HER (paper)"].get_color() != lines["C-Energy (paper)"].get_color()
    assert not any("paper)" in line.get_label() for line in pick_place.get_lines())
    with pytest.raises(KeyError, match=r"no runs for panel\(s\) \['slide-standard'\]"):
        draw_sweep(tmp_path, panels=["slide-standard"])
    table = summary_table(tmp_path, [2], panels=["push-standard"])
    assert "Push: standard goals" in table and "PickAndPlace" not in table


def test_a_panel_without_runs_shows_the_published_values_alone_and_has_no_table_rows(tmp_path, capsys):
    write_run(tmp_path / "push-standard/her/paper/seed0", [0.1, 0.2])
    write_run(tmp_path / "push-standard/cebp_initial/paper/seed0", [0.0, 0.1])
    reference = tmp_path / "paper.csv"
    reference.write_text("panel,sampler,name,epoch,value\nslide-standard-T70,her,HER (paper),50,0.47\n"
                         "slide-standard-T70,cebp_initial,C-Energy (paper),20,0.3\n")
    fig = draw_sweep(tmp_path, panels=["push-standard", "slide-standard-T70"], reference=reference)
    push, slide = fig.axes
    assert slide.get_title() == "Slide: standard goals, 70-step episodes"
    assert [text.get_text() for text in slide.texts] == ["no runs yet"]
    markers = legend(slide)
    assert sorted(markers) == ["C-Energy (paper)", "HER (paper)"]
    assert markers["HER (paper)"].get_color() == legend(push)["HER (1 seed)"].get_color()
    assert slide.get_xlim()[0] == push.get_xlim()[0] == 0
    with pytest.raises(KeyError, match=r"no runs for panel\(s\) \['slide-standard'\]"):
        draw_sweep(tmp_path, panels=["push-standard", "slide-standard"], reference=reference)  # not published
    main([str(tmp_path), "--panels", "push-standard", "slide-standard-T70", "--reference", str(reference),
          "--out", str(tmp_path / "fig.png"), "--table", "2"])
    rows = [line for line in capsys.readouterr().out.splitlines() if line.startswith("| ") and "task" not in line]
    assert len(rows) == 2 and all(row.startswith("| Push: standard goals") for row in rows)


@pytest.mark.parametrize("configurations", [1, 14])
def test_legends_sit_below_their_panels_x_label_however_many_entries(tmp_path, configurations):
    for n in range(configurations):
        write_run(tmp_path / f"push-standard/her/paper-{n}/seed0", [0.1, 0.2])
    write_run(tmp_path / "slide-standard/her/paper/seed0", [0.0, 0.1])
    fig = draw_sweep(tmp_path, title="a title over both panels")
    fig.canvas.draw()  # places the x labels
    renderer = fig.canvas.get_renderer()
    for ax in fig.axes:
        legend, label = ax.get_legend().get_window_extent(renderer), ax.xaxis.label.get_window_extent(renderer)
        assert legend.y1 < label.y0  # display coordinates grow upwards
        assert legend.y0 >= 0  # and the figure holds it
    plt.close(fig)


@pytest.mark.bookkeeping
def test_every_committed_run_folder_is_named_by_its_method_and_superseded_runs_say_so():
    configurations = {
        label for curves_by_label in collect_sweep(COMMITTED_RUNS, "test_success").values() for label in curves_by_label
    }
    labels = {configuration: method_label(configuration) for configuration in configurations}
    for configuration, label in labels.items():
        assert label.split(",")[0].split(" (")[0] in {name.split(" (")[0] for name in SAMPLER_NAMES.values()}
        assert "/" not in label and "_" not in label, label  # no folder syntax left
        superseded = "wnorm" in configuration or (
            not configuration.startswith("her/") and "per_worker" not in configuration
        ) or (configuration.startswith("cper/") and "her_past" not in configuration)
        assert label.endswith("(superseded)") == superseded, (configuration, label)
    assert labels["cebp_initial/paper-per_worker"] == "CEBP (Initial commit)"
    assert labels["cebp_initial/paper-per_worker-wnorm"] == "CEBP (Initial commit), normalised loss (superseded)"
    assert labels["cebp_initial/paper-per_worker-beta0"] == "CEBP (Initial commit), no IS weights"
    assert labels["cebp/paper-wnorm"] == "CEBP (paper form), merged buffer, normalised loss (superseded)"
    assert labels["cper/paper-per_worker-her_past"] == "CPER"
    assert labels["cebp_released/paper"] == "CEBP (released code), merged buffer (superseded)"
    assert {labels[f"{s}/paper-per_worker"] for s in ("per", "ebp", "mep")} == {"PER", "EBP", "MEP"}
    assert method_label("cebp_T0.01/paper-per_worker") == "CEBP (paper form), T = 0.01"
    assert method_label("my_sampler/paper-per_worker-lr3") == "my_sampler, lr3"  # unknown parts kept, not dropped


def test_every_table_column_says_what_its_cells_are(capsys):
    main([str(COMMITTED_RUNS), "--out", "/dev/null", "--panels", "push-standard", "--table", "10",
          "--improvement-at", "10"])
    header = next(line for line in capsys.readouterr().out.splitlines() if line.startswith("| task"))
    assert header == ("| task | method | run folder | seeds | IQM [95% CI] after 10 epochs"
                      " | P(> HER) [95% CI] after 10 epochs | training hours |")


def test_a_tail_only_some_seeds_reached_is_dotted_without_a_band(tmp_path):
    write_run(tmp_path / "push-standard/her/paper/seed0", [0.0, 0.1, 0.2, 0.5])
    write_run(tmp_path / "push-standard/her/paper/seed1", [0.0, 0.3])
    (ax,) = draw_sweep(tmp_path).axes
    solid, tail = ax.get_lines()
    assert solid.get_xdata().tolist() == [1, 2] and solid.get_linestyle() == "-"
    assert tail.get_xdata().tolist() == [2, 3, 4] and tail.get_linestyle() == ":" and tail.get_label().startswith("_")
    (band,) = ax.collections
    assert band.get_paths()[0].vertices[:, 0].max() == 2  # the band covers the epochs all seeds reached
    assert "dotted: epochs that only some seeds reached" in ax.figure.texts[0].get_text()


def test_configurations_keep_the_methods_asked_for_and_their_published_values(tmp_path):
    for sampler in ("her", "cebp_initial", "cper"):
        write_run(tmp_path / f"push-standard/{sampler}/paper-per_worker/seed0", [0.1] * 10)
    write_run(tmp_path / "slide-standard/cper/paper-per_worker-her_past/seed0", [0.1] * 10)
    reference = tmp_path / "paper.csv"
    reference.write_text("panel,sampler,name,epoch,value\npush-standard,her,HER (paper),10,0.5\n"
                         "push-standard,cper,CPER (paper),10,0.15\n")
    (push,) = draw_sweep(tmp_path, configurations=["her/*", "cebp_initial/*"], reference=reference).axes
    assert sorted(legend(push)) == ["CEBP (Initial commit) (1 seed)", "HER (1 seed)", "HER (paper)"]
    with pytest.raises(KeyError, match=r"no configuration matches \['per/\*'\]"):
        select_configurations(collect_sweep(tmp_path, "test_success"), ["her/*", "per/*"])
    with pytest.raises(KeyError, match="reference_panel='slide-standard' has no published values"):
        draw_sweep(tmp_path, reference=reference, reference_panel="slide-standard")
    push, slide = draw_sweep(tmp_path, reference=reference, reference_panel="push-standard").axes
    assert sorted(legend(slide)) == ["CPER (1 seed)", "CPER (paper)", "HER (paper)"]  # push's values on every panel


def test_against_parameter_draws_each_values_iqm_and_the_references_levels(tmp_path):
    for seed, (early, late) in enumerate([(0.2, 0.6), (0.4, 0.8), (0.3, 0.7)]):
        write_run(tmp_path / f"push-temperature/cebp_T0.01/paper/seed{seed}", [0.0, early, late])
        write_run(tmp_path / f"push-standard/her/paper/seed{seed}", [0.0, 0.1 * seed, 0.5 + 0.1 * seed])
    write_run(tmp_path / "push-temperature/cebp_T5/paper/seed0", [0.0, 0.1, 0.9])
    write_run(tmp_path / "push-temperature/cebp_T5/paper/seed1", [0.0, 0.3])  # not yet at epoch 3
    write_run(tmp_path / "push-temperature/cebp_initial/paper/seed0", [0.0, 1.0, 1.0])  # not a temperature
    out = tmp_path / "against.png"
    drawn = plot_against_parameter(tmp_path, "push-temperature", r"cebp_T(.+)/paper", ["push-standard/her/paper"],
                                   [2, 3], out, planned_values=[0.001, 0.01, 5])
    assert drawn[2]["parameter"][0.01][0] == pytest.approx(0.3)  # the IQM of 0.2, 0.3, 0.4
    assert drawn[2]["parameter"][5.0][0] == pytest.approx(0.2) and drawn[2]["parameter"][5.0][3] == 2
    assert drawn[3]["parameter"][5.0] == (0.9, 0.9, 0.9, 1)
    assert drawn[3]["parameter"][0.01][3] == 3 and drawn[3]["parameter"][0.01][0] == pytest.approx(0.7)
    assert drawn[3]["references"]["push-standard/her/paper"][0] == pytest.approx(0.6)
    assert np.asarray(Image.open(out).convert("RGB")).std() > 10


def test_against_parameter_draws_the_returned_values_with_a_hollow_marker_where_seeds_are_missing(tmp_path):
    for seed in range(3):
        write_run(tmp_path / f"sweep/cebp_T0.1/paper/seed{seed}", [0.2 * seed])
        write_run(tmp_path / f"base/her/paper/seed{seed}", [0.5])
    write_run(tmp_path / "sweep/cebp_T1/paper/seed0", [0.4])
    figures = []
    with pytest.MonkeyPatch.context() as patch:  # keep the figure open to read what was drawn
        patch.setattr(plt, "close", figures.append)
        plot_against_parameter(tmp_path, "sweep", r"cebp_T(.+)/paper", ["base/her/paper"], [1], tmp_path / "a.png")
    (ax,) = figures[0].axes
    assert ax.get_xscale() == "log"
    markers = {(line.get_xdata()[0], line.get_ydata()[0]): line for line in ax.get_lines() if line.get_marker() == "o"}
    (solid, hollow) = sorted(markers.items())
    assert solid[0][1] == pytest.approx(0.2) and solid[1].get_markerfacecolor() != "white"
    assert hollow[0][1] == pytest.approx(0.4) and hollow[1].get_markerfacecolor() == "white"
    assert sorted(text.get_text() for text in ax.texts) == ["n=1", "n=3"]
    (her,) = [line for line in ax.get_lines() if line.get_label().startswith("HER")]
    assert list(her.get_ydata()) == [0.5, 0.5]
    plt.close(figures[0])


def test_against_parameter_refuses_what_it_cannot_draw(tmp_path):
    write_run(tmp_path / "sweep/cebp_T0/paper/seed0", [0.4])
    write_run(tmp_path / "sweep/cebp_T2/other/seed0", [0.4])
    with pytest.raises(ValueError, match="not a positive number"):
        plot_against_parameter(tmp_path, "sweep", r"cebp_T(.+)/paper", [], [1], tmp_path / "a.png")
    with pytest.raises(KeyError, match="matches no configuration"):
        plot_against_parameter(tmp_path, "sweep", r"cper_T(.+)/paper", [], [1], tmp_path / "a.png")
    with pytest.raises(ValueError, match="has no group"):
        plot_against_parameter(tmp_path, "sweep", r"cebp_T2/other", [], [1], tmp_path / "a.png")
    with pytest.raises(ValueError, match="reached any of epochs=\\[5\\]"):
        plot_against_parameter(tmp_path, "sweep", r"cebp_T(.+)/other", [], [5], tmp_path / "a.png")
    with pytest.raises(KeyError, match="reference 'base/her/paper' has no runs"):
        plot_against_parameter(tmp_path, "sweep", r"cebp_T(.+)/other", ["base/her/paper"], [1], tmp_path / "a.png")


def write_temperature_study(root):
    """T = 0.01 (3 seeds), T = 5 (2 seeds, one short of epoch 3), HER (3 seeds) and CPER (1 seed, 2 epochs)."""
    for seed, (early, late) in enumerate([(0.2, 0.6), (0.4, 0.8), (0.3, 0.7)]):
        write_run(root / f"push-temperature/cebp_T0.01/paper-per_worker/seed{seed}", [0.0, early, late])
        write_run(root / f"push-standard/her/paper/seed{seed}", [0.0, 0.1 * (seed + 1), 0.5 + 0.1 * seed])
    write_run(root / "push-temperature/cebp_T5/paper-per_worker/seed0", [0.0, 0.1, 0.9])
    write_run(root / "push-temperature/cebp_T5/paper-per_worker/seed1", [0.0, 0.3])
    write_run(root / "push-temperature/cebp_initial/paper-per_worker/seed0", [0.0, 1.0, 1.0])  # not a temperature
    write_run(root / "push-standard/cper/paper-per_worker-her_past/seed0", [0.0, 0.1])
    return ["push-temperature", "--against", r"cebp_T(.+)/paper-per_worker", "--at", "3", "--against-references",
            "push-standard/her/paper", "push-standard/cper/paper-per_worker-her_past"]


def test_against_parameter_table_has_a_row_per_value_planned_or_run_then_per_reference(tmp_path, capsys):
    study = write_temperature_study(tmp_path)
    main([str(tmp_path), "--panels", *study, "--out", str(tmp_path / "against.png"), "--parameter-values", "0.001",
          "0.01", "5", "--table", "2", "3", "--improvement-at", "3", "--parameter-baseline", "0.01"])
    lines = [line for line in capsys.readouterr().out.splitlines() if line.startswith("| ")]
    assert lines[0] == ("| method | run folder | seeds | IQM [95% CI] after 2 epochs | IQM [95% CI] after 3 epochs"
                        " | P(> T = 0.01) [95% CI] after 3 epochs | P(> HER) [95% CI] after 3 epochs"
                        " | training hours |")
    rows = [line.split(" | ") for line in lines[1:]]
    assert [cells[:3] for cells in rows] == [
        ["| CEBP (paper form), T = 0.001", "-", "(not run yet)"],  # planned: seen to be missing
        ["| CEBP (paper form), T = 0.01", "push-temperature/cebp_T0.01/paper-per_worker", "3"],
        ["| CEBP (paper form), T = 5", "push-temperature/cebp_T5/paper-per_worker", "2"],
        ["| HER", "push-standard/her/paper", "3"],
        ["| CPER", "push-standard/cper/paper-per_worker-her_past", "1"],
    ]
    missing, t001, t5, her, cper = rows
    assert missing[3:] == ["-"] * 4 + ["- |"]
    # T = 0.01 after 3 epochs: 0.6, 0.8, 0.7 against HER's 0.5, 0.6, 0.7: wins 1.5 + 3 + 2.5 of 9 pairs
    assert t001[3:5] == ["0.30 [0.20, 0.40]", "0.70 [0.60, 0.80]"]
    assert t001[5] == "(baseline)" and t001[6].startswith("0.78 [")
    assert t001[7] == "0.1 |"  # 9 epochs of 60 s
    assert t5[3:7] == ["0.20 [0.10, 0.30]", "0.90 [0.90, 0.90] (1 seed)", "1.00 [1.00, 1.00]", "1.00 [1.00, 1.00]"]
    assert her[3:5] == ["0.20 [0.10, 0.30]", "0.60 [0.50, 0.70]"]
    assert her[5].startswith("0.22 [") and her[6] == "(baseline)"
    assert cper[3:7] == ["0.10 [0.10, 0.10]", "-", "-", "-"]  # not yet at epoch 3


def test_against_parameter_table_compares_with_a_planned_baseline_only_once_it_has_runs(tmp_path):
    write_temperature_study(tmp_path)
    table = parameter_table(tmp_path, "push-temperature", r"cebp_T(.+)/paper-per_worker", [], [3], improvement_at=[3],
                            parameter_baseline=0.1, planned_values=[0.1])
    rows = [line.split(" | ") for line in table.splitlines()[2:]]
    assert [cells[:3] + cells[4:5] for cells in rows] == [
        ["| CEBP (paper form), T = 0.01", "push-temperature/cebp_T0.01/paper-per_worker", "3", "-"],
        ["| CEBP (paper form), T = 0.1", "-", "(not run yet)", "(baseline)"],
        ["| CEBP (paper form), T = 5", "push-temperature/cebp_T5/paper-per_worker", "2", "-"],
    ]


def test_against_parameter_table_refuses_a_baseline_outside_the_study_and_options_it_cannot_honour(tmp_path, capsys):
    study = write_temperature_study(tmp_path)
    out = ["--out", str(tmp_path / "against.png")]
    with pytest.raises(ValueError, match=r"parameter_baseline=0.1 is not a value of the study; its values \(with"
                                         r" runs or planned\): \['0.001', '0.01', '5'\]"):
        main([str(tmp_path), "--panels", *study, *out, "--parameter-values", "0.001", "--table", "3",
              "--improvement-at", "3", "--parameter-baseline", "0.1"])
    with pytest.raises(ValueError, match=r"improvement_at=\[3\] needs a parameter_baseline or a reference"):
        parameter_table(tmp_path, "push-temperature", r"cebp_T(.+)/paper-per_worker", [], [3], improvement_at=[3])
    for extra, error in (
        (["--table", "3", "--parameter-baseline", "0.01"], "--parameter-baseline goes with --improvement-at"),
        (["--improvement-at", "3"], "--improvement-at goes with --table"),
        (["--table", "3", "--mean-over", "1", "3"], "--mean-over does not go with --against"),
        (["--table", "3", "--improvement-at", "3", "--baseline", "cper"], "--baseline does not go with --against"),
        (["--table", "3", "--tables-out", str(tmp_path / "t.md")], "--tables-out does not go with --against"),
    ):
        with pytest.raises(SystemExit):
            main([str(tmp_path), "--panels", *study, *out, *extra])
        assert error in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main([str(tmp_path), "--table", "3", "--improvement-at", "3", "--parameter-baseline", "0.01"])
    assert "--parameter-baseline goes with --against" in capsys.readouterr().err
    write_run(tmp_path / "push-temperature/cebp_T5.0/paper-per_worker/seed0", [0.1])
    with pytest.raises(ValueError, match="cebp_T5/paper-per_worker and cebp_T5.0/paper-per_worker both read as"
                                         " parameter 5"):
        parameter_table(tmp_path, "push-temperature", r"cebp_T(.+)/paper-per_worker", [], [3])
