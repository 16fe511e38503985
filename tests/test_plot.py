"""The plot command draws a PNG from the runs of a sweep."""
import matplotlib.pyplot as plt
import numpy as np
import pytest
from PIL import Image

from torchrl_cebp.plot import collect_sweep, draw_sweep, iqm_band, main, summary_table


def write_run(folder, success):
    folder.mkdir(parents=True)
    lines = ["epoch,test_success,loss_actor,epoch_s"] + [f"{e},{s},0.1,60" for e, s in enumerate(success)]
    (folder / "progress.csv").write_text("\n".join(lines) + "\n")


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
    assert [ax.get_title() for ax in fig.axes] == ["push-extended", "slide-extended"]
    assert fig.get_suptitle() == "all tasks"


def test_one_task_folder_as_root_is_one_panel_of_its_samplers(tmp_path, capsys):
    for seed, (her, cebp) in enumerate([(0.1, 0.3), (0.2, 0.3)]):
        write_run(tmp_path / f"push-extended/her/paper/seed{seed}", [her])
        write_run(tmp_path / f"push-extended/cebp/paper/seed{seed}", [cebp])
    groups = collect_sweep(tmp_path / "push-extended", "test_success")
    assert {panel: sorted(labels) for panel, labels in groups.items()} == {"push-extended": ["cebp/paper", "her/paper"]}
    main([str(tmp_path / "push-extended"), "--table", "1", "--improvement-at", "1"])
    rows = [line for line in capsys.readouterr().out.splitlines() if line.startswith("| push-extended (paper)")]
    assert [row.split(" | ")[1] for row in rows] == ["cebp", "her"]
    assert rows[0].split(" | ")[4] == "1.00 [1.00, 1.00]"  # every cebp seed above every her seed
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
    her_alone, (cebp, her) = pick_place.get_lines(), push.get_lines()  # the lone her keeps "her/paper" as label
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
    reference.write_text("panel,sampler,name,epoch,value\nslide-standard-T70,her,HER (paper),50,0.47\n"
                         "slide-standard-T70,cper,CPER (paper),50,0.52\n")  # a sampler with no runs
    push, slide = draw_sweep(tmp_path, reference=reference).axes
    lines = {line.get_label().split(" (")[0]: line for line in push.get_lines()}
    slide_lines = {line.get_label(): line for line in slide.get_lines()}
    her_colour = lines["her/paper"].get_color()
    slide_her = slide_lines["her/paper-per_worker (1 seed)"]
    assert slide_her.get_color() == slide_lines["HER (paper)"].get_color() == her_colour
    merged, per_worker = lines["cebp_initial/paper"], lines["cebp_initial/paper-per_worker"]
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
    assert push.startswith("push-standard") and slide.startswith("slide-standard-T70")
    assert "after 3 epochs" not in push and "P(> her) after 2 epochs" in push
    assert "| cebp | 2 | 0.40 [0.40, 0.40] | 1.00 [1.00, 1.00] |" in push
    assert "after 3 epochs" in slide and "P(> her) after 3 epochs" in slide
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
    assert [text.get_text() for text in ax.get_legend().get_texts()] == ["her/paper (2 seeds to epoch 2, 1 seed to 4)"]


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
    assert [text.get_text() for text in ax.get_legend().get_texts()] == ["cebp/paper (1 seed)"]


def test_table_gives_iqm_and_bootstrap_interval_after_n_epochs(tmp_path, capsys):
    for seed, success in enumerate([[0.0, 0.2], [0.0, 0.4], [0.0, 0.6]]):
        write_run(tmp_path / f"push-extended/cebp/paper/seed{seed}", success)
    write_run(tmp_path / "push-extended/her/paper/seed0", [0.1])
    main([str(tmp_path), "--table", "1", "2"])
    rows = {line.split(" | ")[1]: line for line in capsys.readouterr().out.splitlines() if line.startswith("| push")}
    # the preset every configuration shares goes to the task column
    assert rows["cebp"] == "| push-extended (paper) | cebp | 3 | 0.00 [0.00, 0.00] | 0.40 [0.20, 0.60] | 0.1 |"
    assert rows["her"] == "| push-extended (paper) | her | 1 | 0.10 [0.10, 0.10] | - | 0.0 |"
    with pytest.raises(ValueError, match="start at 1"):
        main([str(tmp_path), "--table", "0"])


def test_table_mean_over_a_window_of_epochs(tmp_path, capsys):
    for seed, success in enumerate([[0.0, 0.2, 0.4], [0.0, 0.4, 0.8], [0.2, 0.6]]):
        write_run(tmp_path / f"push-extended/cebp/paper/seed{seed}", success)
    main([str(tmp_path), "--table", "3", "--mean-over", "2", "3"])
    out = capsys.readouterr().out
    assert "| task | configuration | seeds | after 3 epochs | mean over epochs 2-3 | training hours |" in out
    # seeds 0 and 1 reached epoch 3: their means over epochs 2-3 are 0.3 and 0.6
    assert "| push-extended | cebp/paper | 3 | 0.60 [0.40, 0.80] (2 seeds) | 0.45 [0.30, 0.60] (2 seeds) | 0.1 |" in out
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
    rows = {line.split(" | ")[1]: line for line in capsys.readouterr().out.splitlines() if line.startswith("| push")}
    # cebp beats her in (3 + 3 + 1) of 9 pairs, ties none: 7/9
    assert "| 0.78 [" in rows["cebp"]
    assert "(baseline)" in rows["her"]
    with pytest.raises(SystemExit):
        main([str(tmp_path), "--improvement-at", "2"])


def test_table_probability_of_improvement_at_several_epochs(tmp_path, capsys):
    # her leads after 1 epoch in every pair, cebp after 2 in all but one tie: one column per epoch asked for
    for seed, (her, cebp) in enumerate([((0.2, 0.1), (0.1, 0.3)), ((0.3, 0.2), (0.0, 0.2)), ((0.4, 0.4), (0.1,))]):
        write_run(tmp_path / f"push-extended/her/paper/seed{seed}", her)
        write_run(tmp_path / f"push-extended/cebp/paper/seed{seed}", cebp)
    main([str(tmp_path), "--table", "2", "--improvement-at", "1", "2"])
    out = capsys.readouterr().out
    assert "| after 2 epochs | P(> her) after 1 epoch | P(> her) after 2 epochs | training hours |" in out
    rows = {line.split(" | ")[1]: line.split(" | ") for line in out.splitlines() if line.startswith("| push")}
    # after 2 epochs cebp has seeds 0-1 (0.3, 0.2) against her's three (0.1, 0.2, 0.4): (2 + 1.5) / 6
    assert rows["cebp"][4].startswith("0.00 [") and rows["cebp"][5].startswith("0.58 [")
    assert rows["her"][4:6] == ["(baseline)", "(baseline)"]
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
    assert [push.get_title(), pick_place.get_title()] == ["push-standard (paper)", "pick_place-standard (paper)"]
    lines = {line.get_label(): line for line in push.get_lines()}
    assert lines["HER (paper)"].get_xydata().tolist() == [[10, 0.5], [18, 0.97]]
    assert lines["HER (paper)"].get_color() == lines["her (1 seed)"].get_color()
    assert lines["C-Energy (paper)"].get_color() == lines["cebp_initial (1 seed)"].get_color()
    assert lines["HER (paper)"].get_color() != lines["C-Energy (paper)"].get_color()
    assert not any("paper)" in line.get_label() for line in pick_place.get_lines())
    with pytest.raises(KeyError, match=r"no runs for panel\(s\) \['slide-standard'\]"):
        draw_sweep(tmp_path, panels=["slide-standard"])
    table = summary_table(tmp_path, [2], panels=["push-standard"])
    assert "push-standard" in table and "pick_place-standard" not in table


def test_a_panel_without_runs_shows_the_published_values_alone_and_has_no_table_rows(tmp_path, capsys):
    write_run(tmp_path / "push-standard/her/paper/seed0", [0.1, 0.2])
    write_run(tmp_path / "push-standard/cebp_initial/paper/seed0", [0.0, 0.1])
    reference = tmp_path / "paper.csv"
    reference.write_text("panel,sampler,name,epoch,value\nslide-standard-T70,her,HER (paper),50,0.47\n"
                         "slide-standard-T70,cebp_initial,C-Energy (paper),20,0.3\n")
    fig = draw_sweep(tmp_path, panels=["push-standard", "slide-standard-T70"], reference=reference)
    push, slide = fig.axes
    assert slide.get_title() == "slide-standard-T70"
    assert [text.get_text() for text in slide.texts] == ["no runs yet"]
    markers = {line.get_label(): line for line in slide.get_lines()}
    assert sorted(markers) == ["C-Energy (paper)", "HER (paper)"]
    assert markers["HER (paper)"].get_color() == {l.get_label(): l for l in push.get_lines()}["her (1 seed)"].get_color()
    assert slide.get_xlim()[0] == push.get_xlim()[0] == 0
    with pytest.raises(KeyError, match=r"no runs for panel\(s\) \['slide-standard'\]"):
        draw_sweep(tmp_path, panels=["push-standard", "slide-standard"], reference=reference)  # not published
    main([str(tmp_path), "--panels", "push-standard", "slide-standard-T70", "--reference", str(reference),
          "--out", str(tmp_path / "fig.png"), "--table", "2"])
    rows = [line for line in capsys.readouterr().out.splitlines() if line.startswith("| ") and "task" not in line]
    assert len(rows) == 2 and all(row.startswith("| push-standard") for row in rows)


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
