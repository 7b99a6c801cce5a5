"""Ground truth renderers. ``diviewer.reference.mitsuba``: the Mitsuba 3 path tracer (needs the 'train' extra);
``diviewer.reference.progressive``: the viewer's background preview, refined pass by pass on a thread.

Nothing here imports mitsuba at package import time: the viewer and the benchmark run without it.
"""
