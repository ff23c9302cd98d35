"""Finding the physics a model left out: `discover` (locate, name, model, show), the catalogue
of candidate physics, the selection rule, the report; `_emps_study` is the EMPS study."""

from ._catalogue import Term as Term, default_catalogue as default_catalogue
from ._discover import DiscoveryReport as DiscoveryReport, discover as discover
from ._report import figures as figures
from ._select import SelectionRule as SelectionRule
