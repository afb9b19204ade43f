"""The HTTP routes, one router per concern (mounted by ``service.app.create_app``)."""
