"""The emulated EvoLogics modem answers its AT commands from one table (a real pty, pyserial on the
other end, as a driver would talk to it)."""

import serial

from daemon_kit import Daemon, unique


def test_the_emulated_modem_answers_settings_queries_and_unknown_commands(tmp_path):
    link = unique("em")
    pty = tmp_path / "ttyEVO"
    daemon = Daemon(tmp_path, f"""\
channels: {{ac: {{speed_mps: 1500}}}}
vehicles: {{v: {{pose: {{static: [0, 0, 0]}}}}}}
links: {{{link}: {{vehicle: v, address: 4, emulate: {{protocol: evologics, pty: {pty}}}}}}}
""", [link])
    try:
        daemon.wait_for("READY=1")
        port = serial.Serial(str(pty), 19200, timeout=10)

        def ask(command: str) -> str:
            port.write(command.encode() + b"\r\n")
            line = port.read_until(b"\r\n").decode().strip()
            return line

        assert ask("AT?AL") == "4"                      # a setting, from the link's address
        assert ask("AT!AL7") == "OK" and ask("AT?AL") == "7"
        assert ask("AT!AL") == "ERROR WRONG FORMAT"
        assert ask("AT?MODE") == "NET"                  # the network interpreter (issue 18: DUNE wants it)
        assert ask("AT?T") == "0"                       # no delivery yet
        assert ask("ATI7") == "EvoLogics GmbH"
        assert ask("AT?NOSUCH") == "ERROR UNKNOWN COMMAND"
        assert ask("ATH") == "OK"
        port.close()
    finally:
        daemon.close()
