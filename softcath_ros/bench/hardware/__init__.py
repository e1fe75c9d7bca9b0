"""Pressure regulators and load cells on real devices, without ROS (docs/lab.md).

``protocol``: the ASCII line protocols of the serial devices; ``devices``: the backends
(``serial``, ``modbus``, ``sim``) behind one small interface; ``regulator`` and ``scale``: the
state machines the nodes drive with a clock (clamp, vent on command timeout, vent when the device
goes silent). pyserial and pymodbus (the ``hardware`` extra) are imported only by their backends.
"""
