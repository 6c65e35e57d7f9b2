"""Importing this module registers every generator, in the order ``lts360 objects`` lists them."""

from lts360.scenes.objects import plug_gauge  # noqa: F401
from lts360.scenes.objects import pvc_pipe  # noqa: F401
from lts360.scenes.objects import alu_pipe  # noqa: F401
from lts360.scenes.objects import undercut_shaft  # noqa: F401
from lts360.scenes.objects import cut_tube  # noqa: F401
from lts360.scenes.objects import grooved_shaft  # noqa: F401
from lts360.scenes.objects import cable  # noqa: F401
from lts360.scenes.objects import cube  # noqa: F401
