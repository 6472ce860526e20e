import re
from pathlib import Path

import pytest
import yaml

from sr3d_cli.config import ADVANCED, Config, build_config, to_dict, to_layout
from sr3d_cli.errors import ConfigError

DEFAULT_YAML = Path(__file__).resolve().parents[1] / "configs" / "default.yaml"


def test_default_yaml_lists_every_key_with_the_builtin_defaults():
    assert yaml.safe_load(DEFAULT_YAML.read_text()) == to_layout(Config())


def test_every_key_in_default_yaml_has_a_comment():
    for line in DEFAULT_YAML.read_text().splitlines():
        if line.startswith("  ") and ":" in line:
            assert "#" in line, f"no comment on: {line}"


def test_tuning_constants_sit_under_advanced_and_user_keys_do_not():
    layout = yaml.safe_load(DEFAULT_YAML.read_text())
    advanced = layout.pop("advanced")
    assert {s: tuple(keys) for s, keys in advanced.items()} == ADVANCED
    for section, keys in layout.items():
        assert not set(keys) & set(ADVANCED.get(section, ())), section
    user = sum(len(keys) for keys in layout.values())
    assert user < sum(len(keys) for keys in advanced.values())  # most keys are tuning


def test_advanced_keys_are_set_by_either_path_onto_the_same_field(tmp_path):
    path = tmp_path / "c.yaml"
    path.write_text("advanced:\n  align:\n    refine_evals: 40\n  segment:\n    close_radius: 3\n"
                    "segment:\n  min_score: 0.5\n  rough_factor: 3.0\n")
    cfg = build_config(path, ["advanced.grasp.nms_angle=20", "grasp.stride=2"])
    assert cfg.align.refine_evals == 40 and cfg.segment.close_radius == 3
    assert cfg.segment.min_score == 0.5 and cfg.segment.rough_factor == 3.0  # the flat path
    assert cfg.grasp.nms_angle == 20.0 and cfg.grasp.stride == 2


def test_advanced_errors_name_the_key_as_written(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("advanced:\n  align:\n    window: -5\n")
    with pytest.raises(ConfigError, match=r"'advanced.align.window' in .*bad.yaml: must be > 0"):
        build_config(path)
    with pytest.raises(ConfigError, match="'advanced.segment.backend' in --set: segment.backend "
                                          "is a user-facing key"):
        build_config(None, ["advanced.segment.backend=import"])
    with pytest.raises(ConfigError, match="unknown key 'advanced.grasp.nope' in --set"):
        build_config(None, ["advanced.grasp.nope=1"])
    with pytest.raises(ConfigError, match="unknown section 'advanced.synth'"):
        build_config(None, ["advanced.synth.seed=1"])
    with pytest.raises(ConfigError, match="expected advanced.section.key=value"):
        build_config(None, ["advanced.grasp=1"])
    with pytest.raises(ConfigError, match="'advanced.grasp.stride' in --set: expected an "
                                          "integer"):
        build_config(None, ["advanced.grasp.stride=many"])


def test_precedence_defaults_file_set_flags(tmp_path):
    path = tmp_path / "c.yaml"
    path.write_text("synth:\n  scenes: 7\n  seed: 3\n  views: 2\n")
    cfg = build_config(path, ["synth.seed=11", "synth.views=5"], {"synth.views": 9,
                                                                 "synth.scenes": None})
    assert cfg.synth.scenes == 7  # file beats default; a None flag is "not given"
    assert cfg.synth.seed == 11  # --set beats file
    assert cfg.synth.views == 9  # flag beats --set
    assert cfg.synth.lying_fraction == Config().synth.lying_fraction  # untouched default


def test_unknown_key_names_key_and_file(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("evaluate:\n  holez: full\n")
    with pytest.raises(ConfigError, match=r"'evaluate.holez' in .*bad.yaml"):
        build_config(path)


def test_unknown_section_and_wrong_type(tmp_path):
    with pytest.raises(ConfigError, match="unknown section 'evaluat'"):
        build_config(None, ["evaluat.holes=full"])
    with pytest.raises(ConfigError, match="'synth.scenes' in --set: expected an integer"):
        build_config(None, ["synth.scenes=many"])
    with pytest.raises(ConfigError, match="not one of full, ignore"):
        build_config(None, ["evaluate.holes=some"])
    with pytest.raises(ConfigError, match="expected section.key=value"):
        build_config(None, ["scenes=3"])


def test_numbers_and_lists_are_coerced():
    cfg = build_config(None, ["io.depth_scale=1", "evaluate.pred=depth,repaired",
                              "synth.distance=[0.4, 1]"])
    assert cfg.io.depth_scale == 1.0 and isinstance(cfg.io.depth_scale, float)
    assert cfg.evaluate.pred == ["depth", "repaired"]
    assert cfg.synth.distance == [0.4, 1.0]


def test_unreadable_and_invalid_yaml(tmp_path):
    with pytest.raises(ConfigError, match="cannot read config file"):
        build_config(tmp_path / "missing.yaml")
    bad = tmp_path / "broken.yaml"
    bad.write_text("io: [unclosed\n")
    with pytest.raises(ConfigError, match="broken.yaml: config file is not valid YAML"):
        build_config(bad)


def _sr3d_config(*args):
    from click.testing import CliRunner

    from sr3d_cli.cli import cli

    return CliRunner().invoke(cli, ["config", *args])


def test_config_command_prints_the_effective_config_that_config_reads_back(tmp_path):
    path = tmp_path / "mine.yaml"
    path.write_text("grasp:\n  seeds: 40\n  friction: 0.3\n")
    result = _sr3d_config("--config", str(path), "--set", "grasp.seeds=12")
    assert result.exit_code == 0, result.output
    printed = yaml.safe_load(result.output)
    expected = build_config(path, ["grasp.seeds=12"])
    assert printed == to_layout(expected)
    assert printed["grasp"]["seeds"] == 12 and printed["grasp"]["friction"] == 0.3
    # sections in the dataclasses' order, the tuning constants last
    assert list(printed) == [s for s in to_dict(Config()) if s in printed] + ["advanced"]
    again = tmp_path / "printed.yaml"
    again.write_text(result.output)
    assert to_dict(build_config(again)) == to_dict(expected)


def test_config_command_without_a_file_prints_default_yaml_values():
    result = _sr3d_config()
    assert result.exit_code == 0, result.output
    assert yaml.safe_load(result.output) == yaml.safe_load(DEFAULT_YAML.read_text())


def test_config_command_narrows_to_a_section_or_key_and_refuses_unknown_names(tmp_path):
    assert yaml.safe_load(_sr3d_config("synth.distance").output) == {
        "synth": {"distance": [0.35, 0.9]}}
    assert _sr3d_config("repair").output == (
        "repair:\n  outside_render: nearest\n  beyond_mask: true\n  keep_nearer: true\n")
    # a tuning constant is printed where the layout holds it, by either name
    for name in ("segment.close_radius", "advanced.segment.close_radius"):
        assert yaml.safe_load(_sr3d_config(name, "--set", "segment.close_radius=9").output) == {
            "advanced": {"segment": {"close_radius": 9}}}
    both = yaml.safe_load(_sr3d_config("segment").output)
    assert both["segment"]["backend"] == "training-free"
    assert set(both["advanced"]["segment"]) == set(ADVANCED["segment"])
    for name in ("nope", "grasp.nope", "advanced.grasp.friction", "advanced.nope"):
        result = _sr3d_config(name)
        assert result.exit_code == 2 and f"'{name}'" in result.output
    bad = _sr3d_config("--set", "grasp.nope=1")
    assert bad.exit_code == 2 and "grasp.nope" in bad.output


def test_every_command_help_has_an_example():
    from click.testing import CliRunner

    from sr3d_cli.cli import cli

    for name in cli.commands:
        result = CliRunner().invoke(cli, [name, "--help"])
        assert result.exit_code == 0
        assert re.search(rf"Example:\s+sr3d {name} ", result.output), name
