"""hilgate: a hardware-in-the-loop gateway for underwater robot communications.

Applications open links by DCComms id through the Generic Link Interface; hilgate routes each id to a
real modem or to a simulated one whose channel uses the live positions of the vehicles.
"""

__version__ = "0.1.0"
