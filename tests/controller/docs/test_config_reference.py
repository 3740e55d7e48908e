"""The configuration reference page (docs/configuration.md) agrees with the typed config."""

from __future__ import annotations

from pathlib import Path

from controller.docs import config_reference

ROOT = Path(__file__).resolve().parents[3]
PAGE = ROOT / "docs" / "configuration.md"


def test_committed_page_matches_the_code():
    assert PAGE.read_text(encoding="utf-8") == config_reference.render(), (
        f"docs/configuration.md is out of date with the config dataclasses: run "
        f"`{config_reference.COMMAND}` and commit the page")


def test_every_section_and_key_path_is_on_the_page():
    page = config_reference.render()
    for section in config_reference.sections():
        assert f"\n### {section}\n" in page
    for path in ("arm.port", "loop.r_fine_mm", "controller.grasp.guards[].limit",
                 "service.tcp.port", "timing.arm.t0_s", "scene.camera.lens.k1"):
        assert f"| `{path}` |" in page, path


def test_operator_keys_are_at_most_sixty_and_all_exist():
    listed = config_reference.operator_keys()
    assert len(listed) <= 60
    assert sorted(listed) == sorted(config_reference.OPERATOR_KEYS)  # none names a lost key


def test_the_tiers_hold_every_key_once():
    cell = [key.path + key.backend for section in config_reference.sections()
            for key in config_reference.section_keys(section)
            if config_reference.tier_of(key) != "recipe"]
    recipe = [key.path for key in config_reference.recipe_keys()]
    tiered = [key.path + key.backend for by_section in config_reference.tiered().values()
              for keys in by_section.values() for key in keys]
    assert sorted(tiered) == sorted(cell + recipe) and len(set(tiered)) == len(tiered)
    assert "loop.settle_frames" in recipe and "loop.max_loops" not in recipe
    page = config_reference.render()
    assert "| `controller.loop.settle_frames` |" not in page
    assert "| `controller.loop.max_loops` |" in page


def test_docstring_entries_are_parsed_per_key():
    class Example:
        """Config section ``example``.

        step_mm: largest step; a / b: shared text. c, d: another; e: last
        entry. and_key: after a colon.
        """

    docs = config_reference._docstring_entries(Example.__doc__, ["step_mm", "a", "b", "c", "d",
                                                                 "e", "and_key"])
    assert docs["step_mm"] == "Largest step"
    assert docs["a"] == docs["b"] == "Shared text."
    assert docs["c"] == docs["d"] == "Another"
    assert docs["e"] == "Last entry."
    assert docs["and_key"] == "After a colon."


def test_units_types_ranges_and_defaults():
    page = config_reference.render()
    line = next(x for x in page.splitlines() if x.startswith("| `safety.max_step_mm` |"))
    assert line.split(" | ")[1:5] == ["number", "mm", "> 0", "`60`"]
    assert config_reference.unit_of("contact_stiffness_n_per_mm") == "N/mm"
    assert config_reference.range_of({"min": 0.0, "max": 1.0}) == "0 .. 1"
    assert config_reference.default_text("\r") == "\\r"


def test_check_reports_a_stale_page(tmp_path, capsys):
    stale = tmp_path / "configuration.md"
    stale.write_text("old\n", encoding="utf-8")
    page = config_reference.render()
    assert config_reference.write_or_check(page, str(stale), True, "CMD") == 1
    assert "run CMD" in capsys.readouterr().err
    assert config_reference.write_or_check(page, str(stale), False, "CMD") == 0
    assert config_reference.write_or_check(page, str(stale), True, "CMD") == 0
