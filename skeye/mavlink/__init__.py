"""MAVLink for skeye vehicles: the protocol's logic, sans-IO, on pymavlink's common dialect.

How this works: pymavlink encodes and decodes every frame (MAVLink 2, the common dialect);
nothing here writes framing by hand. The modules hold what is ours, as pure classes that take
messages and the time and return messages: ``codec`` (a parser per peer and the encoder),
``modes`` (PX4-compatible custom modes from the flight state, as a table), ``params`` (the
parameter table and its protocol), ``streams`` (the message-interval scheduler), ``mission``
(the mission upload/download protocol and item checks). ``transport`` has the thin UDP, TCP
and serial adapters. The vehicle endpoint that ties them to the pilot's boards is
``skeye.pilot.mavlink_vehicle``; the companion-computer airframe ``skeye.pilot.mavlink_airframe``.
The message set, rates and modes are in docs/protocols/mavlink.md.
"""
