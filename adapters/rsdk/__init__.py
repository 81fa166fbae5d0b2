"""DJI R SDK gimbals (RS 2 / RS 3 / RS 4) over CAN: framing (``protocol``), the command table
(``commands``), CAN segmentation (``can``), candump parsing (``candump``) and the CLI contract
(``describe``). The codec is sans-I/O; links and simulators bind it to a bus elsewhere."""
