"""What a build's ship stage replaces: the model file already there, scored on the ladder's evaluation set by the
ladder's own code, compared with the new model, and kept in WORK/replaced before anything is written over it."""

from __future__ import annotations

import shutil
import time
from pathlib import Path

from diviewer.errors import DiviewerError

REPLACED = "replaced"
"""The work folder's subfolder where the files a ship replaced are kept (one folder per ship, by time)."""


def score_replaced(plan, old: Path, log) -> float:
    """The model file ``old`` scored on the build's evaluation set as each K of the ladder is (`evaluate_evalset`,
    then `evalset_psnr_tm`); an error naming it where it cannot be (another scene's model, not a model)."""
    import json

    from diviewer.builder.scores import evalset_psnr_tm, evalset_scores
    from diviewer.evaluation.scoring import default_jobs
    from diviewer.evaluation.evaluate import evaluate_evalset
    from diviewer.outputs import building

    out = plan.work / "replaced_eval.json"
    with building(plan.work):
        evaluate_evalset([old], plan.evalset_dir, out=out, log=log, jobs=default_jobs())
    return evalset_psnr_tm(evalset_scores(json.loads(out.read_text()), old.stem))


def check_not_worse(plan, old: Path, new_k: int, new_score: float, replace_worse: bool, log) -> dict:
    """Score the model ``old`` that shipping K = ``new_k`` (``new_score`` dB) would replace; refuse, with nothing
    replaced, where it scores better unless ``replace_worse``. Returns the record of what is replaced."""
    try:
        old_score = score_replaced(plan, old, log)
    except DiviewerError as exc:
        if not replace_worse:
            raise DiviewerError(f"the model this build would replace cannot be scored on its evaluation set ({exc}); "
                                f"nothing replaced, the new model is {plan.model(new_k)}; pass --replace-worse to "
                                f"replace it anyway", path=old, field="--ship") from exc
        log(f"{old} cannot be scored on this build's evaluation set ({exc}); replaced as asked (--replace-worse)")
        return {"model": str(old), "evalset_psnr_tm": None}
    verdict = f"{new_score:.2f} dB against {old_score:.2f} dB"
    log(f"ship replaces {old}: on the evaluation set {plan.evalset_dir} the new K = {new_k} scores {verdict} "
        f"(tone-mapped PSNR, every frame)")
    if new_score < old_score and not replace_worse:
        raise DiviewerError(f"the new model (K = {new_k}) scores worse than the one it would replace ({verdict} on "
                            f"{plan.evalset_dir}); nothing replaced, the new model is {plan.model(new_k)}; pass "
                            f"--replace-worse to replace it anyway", path=old, field="--ship")
    return {"model": str(old), "evalset_psnr_tm": old_score, "new_evalset_psnr_tm": new_score}


def keep_replaced(plan, targets: list[Path], log) -> Path | None:
    """Copy every file of ``targets`` that exists into WORK/replaced/<time>/ before the ship writes over it; the
    folder, or None where nothing was there."""
    from diviewer import imageio

    there = [p for p in targets if p.is_file()]
    if not there:
        return None
    kept = plan.work / REPLACED / time.strftime("%Y%m%d_%H%M%S", time.gmtime())
    for p in there:
        with imageio.atomic_path(kept / p.name) as tmp:
            shutil.copyfile(p, tmp)
    log(f"kept the files it replaces in {kept} ({', '.join(p.name for p in there)})")
    return kept
