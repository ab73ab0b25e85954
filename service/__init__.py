"""service: the FastAPI application, thin routes over :mod:`identify` and :mod:`simulate`."""
