"""``leafview bench``: one module per benchmark table (:mod:`.core`, :mod:`.scene`, :mod:`.export`,
:mod:`.shapes`, :mod:`.latency`) and one timing helper (:mod:`.timing`)."""
