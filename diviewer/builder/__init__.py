"""`diviewer build`: one resumable pipeline from a scene and a recipe to a shipped model (docs/build.md).

`plan` resolves the recipe into stages with estimates (`costs`: measured per-frame and per-step figures, scaled
to the user's scene by `calibrate`: the scene timed here, or a previous build's actuals, kept by `actuals`),
`pipeline` runs them, `state` records what finished, `summary` writes the last lines, `command` is the command
line.
"""
