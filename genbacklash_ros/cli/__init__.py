"""The ``genbacklash`` command line: one module per subcommand group."""
