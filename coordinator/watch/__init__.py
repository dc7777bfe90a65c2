"""``surge watch``: a live map of a running fleet in the browser, or a finished run played back.

:mod:`~coordinator.watch.citymap` draws what does not change (streets,
sectors, venues and their events), :mod:`~coordinator.watch.view` turns the
fleet's minutes into frames, :mod:`~coordinator.watch.live` feeds it from the
bus as a read-only ``observer``, :mod:`~coordinator.watch.replay` from a
results file, and :mod:`~coordinator.watch.server` serves the page in
``static/`` and streams the frames over a websocket.  The command line is
:mod:`coordinator.cli.watch`.
"""
