"""The wire and the bus: msgpack messages, key expressions and zenoh sessions."""
