"""The closed-loop simulator (``alloc sim``): the seed's scenarios flown with any allocator.

Where things live: :mod:`sim.model` (vehicle, failure, controller designs, pilot),
:mod:`sim.settings` (the run settings, defined once, and :class:`~sim.settings.LoopSpec`),
:mod:`sim.engine` (:func:`~sim.engine.simulate`) on the compiled step of :mod:`sim.packed`,
:mod:`sim.injection` (failure injection), :mod:`sim.blocks` (plant, actuators, delay, noise),
:mod:`sim.allocation` (the allocator in the loop), :mod:`sim.scenarios` (the registry and the
scenarios), :mod:`sim.user_vehicle` and :mod:`sim.autodesign` (a vehicle file's model, flown with
the seed's section 4.3 design), :mod:`sim.result` (the result and its metrics), :mod:`sim.cli` and
:mod:`sim.cli_settings` (the command and its settings' options).
Importing this package imports none of them.
"""
