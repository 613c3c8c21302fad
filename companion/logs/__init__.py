"""Flight logs read back: the companion's CSV or any MAVLink .tlog, and the figures drawn from them.

May import: ``live`` (log format, pymavlink set-up), ``mission``, ``errors``; nothing imports it but commands.
"""
