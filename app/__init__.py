"""The ``rig`` command line and the demo: thin layers over library functions."""
