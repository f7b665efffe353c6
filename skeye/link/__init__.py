"""Links to a vehicle (TCP or serial) speaking the vehicle packet protocol."""
