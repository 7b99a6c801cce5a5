"""Recipes as files: the shipped ones match their model cards, bad files are refused naming file and field, and
`diviewer train` resolves recipe, checkpoint and options in that order."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import pytest

from diviewer.errors import DiviewerError
from diviewer.paths import models_dir
from diviewer.commands.parser import CommandParser, arguments
from diviewer.commands.train import add_parser as add_train_parser, resolve_config
from diviewer.train.config import TrainConfig
from diviewer.train.recipe import DEFAULT_RECIPE, load_recipe, shipped_recipes

CARDS = sorted(p.stem for p in models_dir().glob("*.onnx")
               if json.loads(p.with_suffix(".json").read_text()).get("recipe"))


def test_the_shipped_recipes_are_cornell_sponza_and_the_papers():
    assert {"cornell", "sponza", "paper"} <= set(shipped_recipes())
    paper = load_recipe("paper")
    # What the project calls the paper's recipe: TrainConfig's defaults (pix2pix: L1 100 + GAN, Adam 2e-4, batch 4).
    defaults = TrainConfig(data=".", out=".")
    for field in ("K", "gan_weight", "lambda_L1", "lr", "beta1", "batch_size", "epochs", "target", "upsample",
                  "norm", "gan_mode", "divide_albedo"):
        assert paper.train[field] == getattr(defaults, field), field
    assert paper.ks() == (32, 64, 128) and paper.capture["width"] == 256


@pytest.mark.parametrize("card", CARDS)
def test_a_shipped_cards_recipe_is_its_scenes_recipe_file(card):
    """Every setting the card's recipe records is the recipe file's (the file is the card's recipe, as TOML)."""
    meta = json.loads((models_dir() / f"{card}.json").read_text())
    rec = load_recipe(meta["scene"])
    cfg = json.loads(json.dumps(TrainConfig(data=".", out=".", **rec.train).to_dict(), default=str))  # as the card
    # a rung of the recipe's K ladder other than [train]'s K is the recipe with K overridden (diviewer build --ks)
    overrides = meta["recipe"]["train"].get("recipe", {}).get("overrides", {})
    # an override the file has taken in since (sponza's structure term: trained as an option, then made the recipe's)
    taken = {k for k, v in overrides.items() if k in rec.train and rec.train[k] == v}
    assert set(overrides) - taken <= {"K"} and overrides.get("K", meta["K"]) in rec.ks()
    cfg.update(overrides)
    for key, value in meta["recipe"]["train"].items():
        if key == "recipe":  # the record of the file as training read it (its sha256 then): the same recipe
            # the shipped file, or a copy of it kept beside a build (every setting is compared below)
            assert value["name"] == rec.name and Path(value["file"]).name == f"{rec.name}.toml"
            continue
        assert cfg[key] == value, key
    cap = meta["recipe"]["capture"]
    assert {**rec.capture, "split_fractions": list(rec.capture["split_fractions"])} == {
        **{k: v for k, v in cap.items()}, "width": meta["resolution"][0], "height": meta["resolution"][1]}
    assert meta["K"] in rec.ks() and meta["ladder"]["chosen_K"] == meta["K"]
    for name in (meta["ladder"]["file"], meta["ladder"].get("curves")):  # what the card names ships beside it
        assert name is None or (models_dir() / name).is_file(), name
    assert bool(rec.export.get("fp16")) == (meta["precision"] == "fp16")
    assert bool(rec.export.get("half_weights")) == (meta["precision"] == "fp32" and meta.get("weights") == "fp16")
    assert bool(rec.export.get("int8_weights")) == (meta.get("weights") == "int8")


@pytest.mark.parametrize("card", CARDS)
def test_a_shipped_card_names_the_build_that_rebuilds_it_in_the_json_and_the_onnx_alike(card):
    from diviewer.contract.runtime import read_metadata

    meta = json.loads((models_dir() / f"{card}.json").read_text())
    assert meta["rebuild"] == f"diviewer build --scene {meta['scene']}"
    assert read_metadata(models_dir() / f"{card}.onnx") == meta


def test_the_default_is_the_best_measured_recipe_not_the_papers():
    assert DEFAULT_RECIPE == "cornell"
    args = _parse(["--data", "d", "--out", "o"])
    cfg = resolve_config(args)
    assert cfg.gan_weight == 0.0 and cfg.target == "indirect" and cfg.divide_albedo and cfg.K == 8
    assert cfg.recipe["name"] == "cornell" and cfg.recipe["file"] == "assets/recipes/cornell.toml"
    assert cfg.recipe["sha256"] == load_recipe("cornell").sha256 and cfg.recipe["overrides"] == {}


def test_the_content_hash_ignores_comments_and_the_description_and_follows_every_value(tmp_path):
    text = (Path(load_recipe("cornell").path)).read_text()
    shipped = load_recipe("cornell")
    (tmp_path / "cornell.toml").write_text("# a new comment\n" + text.replace('description = "', 'description = "x'))
    edited = load_recipe(tmp_path / "cornell.toml")
    assert edited.sha256 != shipped.sha256 and edited.content_sha256() == shipped.content_sha256()
    (tmp_path / "cornell.toml").write_text(text.replace("lr = 2e-4", "lr = 3e-4"))
    assert load_recipe(tmp_path / "cornell.toml").content_sha256() != shipped.content_sha256()
    # the ladder's widths are the build's own key ("ks"): a longer ladder resumes a build, another tolerance does not
    assert "K = [8, 16]" in text and "tolerance_db = 0.5" in text
    (tmp_path / "cornell.toml").write_text(text.replace("K = [8, 16]", "K = [8, 16, 32]"))
    assert load_recipe(tmp_path / "cornell.toml").content_sha256() == shipped.content_sha256()
    (tmp_path / "cornell.toml").write_text(text.replace("tolerance_db = 0.5", "tolerance_db = 0.25"))
    assert load_recipe(tmp_path / "cornell.toml").content_sha256() != shipped.content_sha256()
    # a size cap re-picks a finished build's ladder and trains nothing again (diviewer.builder.pipeline._stale)
    (tmp_path / "cornell.toml").write_text(text.replace("tolerance_db = 0.5", "tolerance_db = 0.5\nmax_mb = 8"))
    capped = load_recipe(tmp_path / "cornell.toml")
    assert capped.max_mb == 8.0 and shipped.max_mb is None
    assert capped.content_sha256() == shipped.content_sha256() and capped.model_sha256() == shipped.model_sha256()

def test_options_override_single_fields_and_are_recorded(tmp_path):
    cfg = resolve_config(_parse(["--data", "d", "--out", "o", "--recipe", "paper", "--k", "64", "--lr", "1e-4",
                                 "--device", "cpu"]))
    paper = load_recipe("paper")
    assert (cfg.K, cfg.lr, cfg.gan_weight, cfg.target, cfg.device) == (64, 1e-4, 1.0, "full", "cpu")
    assert cfg.recipe["name"] == "paper" and cfg.recipe["overrides"] == {"K": 64, "lr": 1e-4}
    assert cfg.epochs == paper.train["epochs"]
    own = tmp_path / "mine.toml"
    own.write_text('[recipe]\nname = "mine"\n[train]\nK = 4\nndf = 8\n')
    cfg = resolve_config(_parse(["--data", "d", "--out", "o", "--recipe", str(own)]))
    assert (cfg.K, cfg.ndf, cfg.recipe["name"], cfg.recipe["file"]) == (4, 8, "mine", str(own))
    assert cfg.gan_weight == TrainConfig(data=".", out=".").gan_weight, "fields a recipe leaves out: TrainConfig's"


def test_a_resume_keeps_the_checkpoints_settings_and_recipe_unless_one_is_given():
    old = TrainConfig(data="d", out="o", K=4, seed=3, recipe=load_recipe("paper").record({"K": 4})).to_dict()
    cfg = resolve_config(_parse(["--data", "d", "--out", "o", "--resume"]), old)
    assert (cfg.K, cfg.seed, cfg.gan_weight, cfg.recipe["name"]) == (4, 3, 1.0, "paper")
    cfg = resolve_config(_parse(["--data", "d", "--out", "o", "--resume", "--recipe", "cornell"]), old)
    assert (cfg.K, cfg.gan_weight, cfg.recipe["name"]) == (8, 0.0, "cornell")  # check_resume then refuses K 4 -> 8


@pytest.mark.parametrize("text,field", [
    ("[train]\nKK = 4\n", "train.KK"),
    ("[train]\ndata = 'x'\n", "train.data"),
    ("[capture]\nfps = 4\n", "capture.fps"),
    ("[ladder]\nK = [16, 8]\n", "ladder.K"),
    ("[ladder]\nwidths = [8]\n", "ladder.widths"),
    ("[ladder]\nmax_mb = 0\n", "ladder.max_mb"),
    ("[ladder]\nmax_mb = '8'\n", "ladder.max_mb"),
    ("[ladder]\nmax_mb = nan\n", "ladder.max_mb"),
    ("[recipe]\nauthor = 'me'\n", "recipe.author"),
    ("[training]\nK = 4\n", "training"),
    ("[train]\nK = -1\n", "train.K"),
    ("[train]\nupsample = 'bilinear'\n", "train.upsample"),
    ("[evalset]\nspp = 8\nladder = [16]\n", "evalset.ladder"),
    ("[train\nK = 4\n", "not valid TOML"),
    ("[capture]\nspp = 64\nrefine_from = 64\n", "capture.refine_from"),
    ("[capture]\nspp = 64\nrefine_from = 0\n", "capture.refine_from"),
    ("[capture]\nspp = 64\nrefine_from = 8.5\n", "capture.refine_from"),
])
def test_a_bad_recipe_is_refused_naming_the_file_and_the_field(tmp_path, text, field):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(DiviewerError) as e:
        load_recipe(path)
    assert str(path) in str(e.value) and field in str(e.value)


def test_unknown_recipe_names_list_the_shipped_ones():
    with pytest.raises(DiviewerError, match="shipped recipes: .*cornell.*paper"):
        load_recipe("nonesuch")
    with pytest.raises(DiviewerError, match="recipe file not found"):
        load_recipe("missing/recipe.toml")


def test_every_settings_field_a_recipe_can_set_has_a_spec():
    """Each table's keys are its dataclass's fields, each with a spec (type, range) in `recipe_fields`: a field added
    to a dataclass without one fails here, rather than reaching a recipe unchecked."""
    import dataclasses

    from diviewer.data.capture import CaptureSettings
    from diviewer.data.truth_filter import TruthFilter
    from diviewer.evaluation.evalset import EvalSetSettings
    from diviewer.train import recipe_fields as rf
    from diviewer.train.export import ExportSettings
    from diviewer.train.recipe import CAPTURE_EXTRA, NOT_TRAIN

    def names(cls):
        return {f.name for f in dataclasses.fields(cls)}

    assert set(rf.CAPTURE) == names(CaptureSettings) | set(CAPTURE_EXTRA)
    assert set(rf.EVALSET) == names(EvalSetSettings)
    assert set(rf.TRAIN_FIELDS) == names(TrainConfig) - set(NOT_TRAIN)
    assert set(rf.EXPORT) == names(ExportSettings)
    assert set(rf.TRUTH_FILTER) == names(TruthFilter)
    for specs, obj in ((rf.CAPTURE, CaptureSettings()), (rf.EVALSET, EvalSetSettings()), (rf.EXPORT, ExportSettings()),
                       (rf.TRUTH_FILTER, TruthFilter()), (rf.TRAIN_FIELDS, TrainConfig(data=".", out="."))):
        for name in names(type(obj)) & set(specs):
            specs[name].check(getattr(obj, name))  # every default is a value its own spec takes


def _parse(argv: list[str]) -> argparse.Namespace:
    ap = argparse.ArgumentParser()
    add_train_parser(ap.add_subparsers(dest="command"))
    return ap.parse_args(["train", *argv])


def test_refine_from_is_the_captures_lower_count_and_part_of_what_the_recipe_asks(tmp_path):
    """[capture] refine_from: a recipe key beside CaptureSettings' fields; the capture settings are the truth asked
    for (spp), and the recipe's content changes with it."""
    from diviewer.train.recipe import capture_settings, refine_from

    (tmp_path / "a.toml").write_text("[capture]\nspp = 256\nrefine_from = 64\n")
    (tmp_path / "b.toml").write_text("[capture]\nspp = 256\n")
    a, b = load_recipe(tmp_path / "a.toml"), load_recipe(tmp_path / "b.toml")
    assert refine_from(a) == 64 and refine_from(b) is None
    assert capture_settings(a) == capture_settings(b) and capture_settings(a).spp == 256
    assert a.content_sha256() != b.content_sha256()


def test_sponzas_refining_recipe_captures_what_the_64_spp_recipe_captured():
    """Sponza's recipes refine one another's sets: the 64-spp build's capture (sponza_walk64.toml) is the first stop's
    (sponza_filtered128.toml), whose 128-spp set the filtered recipe's (sponza_filtered.toml: the shipped recipe with
    its truth filtered before training) refines, whose 256-spp set the 512-spp build (sponza_walk512.toml) takes for
    its capture, and that one's refined set the 768-spp build (sponza_walk768.toml): each must ask for the capture it
    is given (its settings at refine_from spp), or the capture stage would refuse it; each trains and scores as the
    64-spp recipe does, and exports with int8-stored weights."""
    from diviewer.data.truth_filter import TruthFilter
    from diviewer.train.recipe import capture_settings, refine_from, truth_filter

    recipes = Path(__file__).parents[2] / "assets" / "recipes"
    walk = load_recipe(recipes / "sponza_walk64.toml")
    refined = load_recipe("sponza")
    assert refine_from(refined) == capture_settings(walk).spp == 64 and capture_settings(refined).spp == 256
    assert refine_from(walk) is None
    assert capture_settings(refined, spp=refine_from(refined)) == capture_settings(walk)
    assert {k: v for k, v in refined.train.items()} == walk.train and refined.ks() == walk.ks()
    assert refined.evalset == walk.evalset
    # the models since the first store their inner weights as int8 where it stored float16 (docs/training.md)
    int8 = {**{k: v for k, v in walk.export.items() if k != "half_weights"}, "int8_weights": True}
    assert walk.export.get("half_weights") and refined.export == int8
    # the ladder's recipe since 2026-12-02: the shipped one, its refined truth filtered before training; since
    # 2026-12-03 it refines the 128-spp set of its first stop (sponza_filtered128.toml), which refines the capture
    filtered = load_recipe(recipes / "sponza_filtered.toml")
    first = load_recipe(recipes / "sponza_filtered128.toml")
    assert refine_from(first) == 64 and capture_settings(first).spp == refine_from(filtered) == 128
    assert capture_settings(first, spp=64) == capture_settings(walk)
    assert capture_settings(filtered, spp=128) == capture_settings(first)
    others = {"truth_filter", "refine_from", "spp"}
    assert {k: v for k, v in filtered.capture.items() if k not in others} == {
        k: v for k, v in refined.capture.items() if k not in others} == {
        k: v for k, v in first.capture.items() if k not in others}
    assert capture_settings(filtered).spp == capture_settings(refined).spp == 256
    # the first stop's filter since 2026-12-04: two levels with a range term (docs/sponza.md, "The range term on
    # frames it was not chosen on"); the 256-spp ladder's keeps one level, chosen before the range term
    assert truth_filter(filtered) == TruthFilter(levels=1, normal_power=32.0, plane=0.01)
    assert truth_filter(first) == TruthFilter(levels=2, normal_power=32.0, plane=0.01, range_sigma=0.6)
    assert truth_filter(refined) is None and truth_filter(walk) is None
    for r in (filtered, first):
        assert (r.train, r.evalset, r.export, r.ks(), r.max_mb) == (
            refined.train, refined.evalset, refined.export, refined.ks(), refined.max_mb)

    # the 512-spp truth refines the shipped recipe's 256-spp set (its settings at 256), itself the 64-spp capture's
    twice = load_recipe(recipes / "sponza_walk512.toml")
    assert refine_from(twice) == capture_settings(refined).spp == 256 and capture_settings(twice).spp == 512
    assert capture_settings(twice, spp=refine_from(twice)) == capture_settings(refined)
    assert capture_settings(twice, spp=64) == capture_settings(walk)
    assert twice.train == walk.train and twice.ks() == walk.ks() and twice.evalset == walk.evalset
    assert twice.export == refined.export and twice.ladder == refined.ladder
    # the ladder's recipe: that 512-spp set refined again to 768 (the set is the capture its build takes)
    ladder = load_recipe(recipes / "sponza_walk768.toml")
    assert refine_from(ladder) == capture_settings(twice).spp == 512 and capture_settings(ladder).spp == 768
    assert capture_settings(ladder, spp=refine_from(ladder)) == capture_settings(twice)
    assert ladder.train == walk.train and ladder.ks() == walk.ks() == (8, 16, 32) and ladder.evalset == walk.evalset
    assert ladder.export == refined.export and ladder.ladder == refined.ladder


def test_train_help_says_what_the_default_recipe_sets_beside_the_papers_defaults():
    """A plain `diviewer train` runs the default recipe, so its --help shows the recipe's value of each option the
    recipe sets (K, epochs, target...) beside TrainConfig's default, and lists every shipped recipe."""
    ap = CommandParser()
    sub = ap.add_subparsers(dest="command")
    add_train_parser(sub)
    train = sub.choices["train"]
    helps = {a.dest: a.help for a in arguments(train)}
    given = load_recipe(DEFAULT_RECIPE).train
    assert f"[the {DEFAULT_RECIPE} recipe: {given['K']}]" in helps["K"]
    assert f"[the {DEFAULT_RECIPE} recipe: {given['epochs']}]" in helps["epochs"]
    assert f"[the {DEFAULT_RECIPE} recipe: {given['target']}]" in helps["target"]
    assert "recipe:" not in helps["data"] and "recipe:" not in helps["resume"]
    assert all(name in helps["recipe"] for name in shipped_recipes())
