"""App: what every command shares, so ``commands/`` holds one module per command: argument groups (``arguments``), the flags read once into typed options (``options``, ``config_file``), the vehicle file loaded once (``vehicle``: the one place below the commands that opens one), a flight assembled once (``flight``), a result printed (``run_result``).

May import: every layer below the commands (``core``, ``sim``, ``mission``, ``mav``, ``live``, ``bus``, ``security``, ``logs``, ``ident``, ``preflight``, ``profiles``, ``view``, ``vehicle``, ``progress``, ``errors``, ``secretfile``, ``__init__``); never ``commands``.
"""
