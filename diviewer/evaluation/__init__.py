"""Evaluation: an evaluation set made (evalset), models scored on it (evaluate), and what both share: the set's
frames read and checked (frames; `iter_frames` hands each frame's inputs, output, truth and tone map), the
per-frame metrics (scoring), a training truth's margin (truthmargin) and the linear baseline (baseline)."""
