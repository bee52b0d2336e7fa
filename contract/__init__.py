"""The modal-table contract that modal (measured modes) and models (predicted modes) both write and
compare and reports read: the modal table (contract.table) and the MAC of mode shapes (contract.mac)."""
