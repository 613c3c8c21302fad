"""MAVLink plumbing both ends of a link share (the companion and ``sitl_plant``): opening links (serial too), signing keys, sockets, the mission protocol (mission_transfer).

May import: pymavlink, ``errors``, ``secretfile``; nothing of the loop, so the plant stays loop-free.
"""
