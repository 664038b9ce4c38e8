"""One router per resource: allocation, methods, AMS, vehicles (with their events), system.

The telemetry routes (:mod:`.telemetry`) are per vehicle: they hang under the vehicles'
router, so the application includes them with it.
"""

from . import telemetry, vehicles

vehicles.router.include_router(telemetry.router)
