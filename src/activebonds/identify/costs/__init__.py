"""The costs a fit minimises, each one module behind the :class:`~activebonds.identify.costs.base.Cost` protocol, found by name in :data:`COSTS`."""
