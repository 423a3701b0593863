"""The HTTP layer: routes that hand requests to :func:`service.solvers.dispatch.dispatch`."""
