"""HTTP layer of the allocation toolkit: allocations, vehicles and their health over REST.

The service turns JSON into an :class:`alloc.Problem` and a :class:`alloc.Result` into
JSON, nothing more.  Start it with ``alloc serve`` / ``make run`` or
:func:`service.main.serve`; build the ASGI app with :func:`service.main.create_app`.
"""
