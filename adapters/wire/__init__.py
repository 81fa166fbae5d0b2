"""What the DJI wire protocols share: CRC engines, field layouts and the resynchronising
receive buffer. Standard library only (sans-I/O: no sockets, threads or clocks)."""
