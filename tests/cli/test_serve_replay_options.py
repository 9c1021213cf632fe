"""``interprim serve --replay`` reads recordings with the same options as ``interprim fit`` (one option group):
a BVH folder in centimetres, and a ROS bag with its topics."""

import numpy as np
from test_loaders_mocap import SKELETON, _cli, write_bvh
from test_loaders_ros import bag_path, two_agent_bag

from interprim.datasets import load_demonstrations


def _serve_replays(argv):
    """Parse ``interprim serve`` arguments and attach the replays as the command does (without listening)."""
    from interprim.cli import build_parser
    from interprim.cli._common import recording_options
    from interprim.cli.serve import _attach_replays, _attach_units, _split_units
    from interprim.server.models import load_models

    args = build_parser().parse_args(["serve", *map(str, argv)])
    models = load_models(args.models)
    labels, length_unit = _split_units(args.units, args.length_unit)
    _attach_units(models, labels)
    _attach_replays(models, args.replay, dict(recording_options(args), max_nan_gap=args.max_nan_gap,
                                              length_unit=length_unit))
    return models


def test_serve_replays_a_bvh_folder_in_centimetres(tmp_path, capsys):
    rng = np.random.default_rng(0)
    folder = tmp_path / "bvh"
    folder.mkdir()
    for k in range(5):
        s = np.linspace(0, 1, 35 + 2 * k)
        lift = rng.uniform(30, 60) * (3 * s**2 - 2 * s**3)
        write_bvh(folder / f"h{k}.bvh", np.column_stack([lift, 0 * s, 10 * s, -lift * 0.9, 0 * s, -10 * s]),
                  frame_time=1 / 30, head=SKELETON)
    model = tmp_path / "m.npz"
    code, _, err = _cli(["fit", "--model", "ip", folder, "--joints", "A_Hand,B_Hand", "--length-unit", "cm",
                         "--observed", "A_Hand_*",
                         "--n-basis", "5", "-o", model], capsys)
    assert code == 0, err
    truth = load_demonstrations(folder, joints="A_Hand,B_Hand", length_unit="cm")  # metres
    for flags in (["--units", "cm"], ["--length-unit", "cm"]):
        models = _serve_replays([model, "--replay", f"m={folder}", "--joints", "A_Hand,B_Hand", *flags])
        replay = models["m"].meta["replay"]
        assert len(replay["interactions"]) == 5
        for it, d in zip(replay["interactions"], truth.demos):
            np.testing.assert_allclose(it["observed"], d[:, :3], atol=1e-6)  # the file's own frames, in metres
            np.testing.assert_allclose(it["controlled_truth"], d[:, 3:], atol=1e-6)
    # --units MODEL=... still labels the columns, beside a bare length unit
    models = _serve_replays([model, "--replay", f"m={folder}", "--joints", "A_Hand,B_Hand", "--units", "cm",
                             "--units", "m=m,m,m,m,m,m"])
    assert models["m"].units == ["m"] * 6
    # without the unit the same folder is read in centimetres: 100 times too large for the model
    models = _serve_replays([model, "--replay", f"m={folder}", "--joints", "A_Hand,B_Hand"])
    far = models["m"].meta["replay"]["interactions"][0]["observed"]
    np.testing.assert_allclose(far, truth.demos[0][:, :3] * 100, atol=1e-4)
    code, _, err = _cli(["serve", model, "--replay", f"m={folder}", "--units", "cm", "--length-unit", "mm"], capsys)
    assert code == 1 and "two length units for the --replay recordings: cm, mm" in err


def test_serve_replays_a_bag_with_its_topics(tmp_path, capsys):
    path = bag_path(tmp_path, "ros1")
    two_agent_bag("ros1", starts=(10.0, 12.0, 14.0, 16.0), n=30, marker="/start").write(path)
    model = tmp_path / "b.npz"
    topics = "/human/wrist,/robot/joint_states"
    code, out, err = _cli(["fit", "--model", "ip", path, "--topics", topics, "--split-topic", "/start", "--n-basis",
                           "5", "-o", model],
                          capsys)
    assert code == 0, err
    code, _, err = _cli(["serve", model, "--replay", f"b={path}"], capsys)
    assert code == 1 and "a ROS bag needs topics OBSERVED,CONTROLLED" in err.replace("--topics", "topics")
    models = _serve_replays([model, "--replay", f"b={path}", "--topics", topics, "--split-topic", "/start"])
    replay = models["b"].meta["replay"]
    # both streams on the model's grid (dt 0.02 s from where both have started), as 'fit --resample 0.02' reads them
    truth = load_demonstrations(path, topics=topics, split_topic="/start", resample_dt=0.02)
    assert len(replay["interactions"]) == 4 and replay["columns"] == truth.columns
    for it, d in zip(replay["interactions"], truth.demos):
        np.testing.assert_allclose(it["observed"], d[:, :3], atol=1e-6)
        np.testing.assert_allclose(it["controlled_truth"], d[:, 3:], atol=1e-6)
