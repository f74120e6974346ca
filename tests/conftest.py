import os
import sys

# Tests import small helpers from this folder (netkit) without making tests a package.
sys.path.insert(0, os.path.dirname(__file__))
