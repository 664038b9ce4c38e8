"""One router per resource: allocation, methods, AMS, vehicles (with their events), system."""
