"""`diviewer build`: one resumable pipeline from a scene and a recipe to a shipped model (docs/build.md).

`plan` resolves the recipe into stages with estimates (`costs`: measured per-frame and per-step figures),
`pipeline` runs them, `state` records what finished, `command` is the command line.
"""
