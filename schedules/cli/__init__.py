"""The ``compose`` command line; nothing imports these modules."""
