"""The studio: a room for every designer on one server, and beyond one machine on Dask (`somwidget serve --studio`).

Rooms sit above the model: each room is a Session of its own (its clay, controls, settings, undo history and autosave
folder) with a view hub of its own, so its views (the room's page on a desktop or in a headset, a notebook through
`somwidget.join`) share that room alone.

    limits.py    what a worker takes (rooms, nodes a room, memory), room names
    rooms.py     the rooms of one process: made, opened, parked when idle, brought back from their folders
    thumbs.py    a room's clay made small for the wall
    host.py      a worker's room server (the front's calls, the rooms' websockets)
    worker.py    a worker process; workers.py: one a GPU on this machine; dask_rooms.py: rooms on Dask workers
    places.py    where rooms live, as the front sees them (this process, or a worker: websockets relayed)
    front.py     the directory of rooms: placement on the least loaded worker, a dead worker's rooms brought back
    access.py    the teacher's, the class's and each room's token
    routes.py    the browsers' routes (/, /api/rooms, /wall, /r/<name>/...); wall.py: the wall's feed; static/
    remote.py    a room from Python: `somwidget.join(url)` (and its notebook view, remote_widget.py)
    serve.py     `somwidget serve --studio`, and StudioServer for tests and benchmarks
"""
