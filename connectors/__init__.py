"""Connectors: one module per plant protocol (Modbus TCP, OPC UA), one task per device with
back-off; they only read from the plant."""
