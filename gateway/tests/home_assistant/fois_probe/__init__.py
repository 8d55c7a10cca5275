"""The FOIS gateway tests' window into Home Assistant.

Loaded as a custom integration from the test's config directory, it writes
what a user of this Home Assistant sees to ``fois_probe.json`` every half
second (written to a temporary file, then renamed): the version, the
config entries and their state (MQTT: ``loaded``), every
entity's state and attributes, the device and entity registries, how many
state changes each entity has had (the recorder writes one row per state
change), the rows per entity in the recorder's database, and every
warning or error logged. It also carries out service calls the test asks
for: a file ``fois_probe_requests/<name>.json`` holding
``{"domain": ..., "service": ..., "data": {...}}`` is called once, then
renamed to ``<name>.done`` (or ``<name>.failed`` with the reason).

No login, token or HTTP client is needed to read any of it, so the test
does not depend on the frontend, onboarding or the REST API, which change
between releases; the registries' attributes it reads exist in every
release the gateway supports.
"""

from __future__ import annotations

from collections import Counter
from datetime import timedelta
import json
import logging
import os
import asyncio
import sqlite3
import traceback

from homeassistant.const import EVENT_STATE_CHANGED, __version__
from homeassistant.core import Event, HomeAssistant, callback
from homeassistant.helpers import device_registry as dr, entity_registry as er
from homeassistant.helpers.event import async_track_time_interval

DOMAIN = "fois_probe"
OUT = "fois_probe.json"
REQUESTS = "fois_probe_requests"
INTERVAL = timedelta(seconds=0.5)


class _Collect(logging.Handler):
    """Keeps every warning and error logged while Home Assistant runs."""

    def __init__(self) -> None:
        super().__init__(level=logging.WARNING)
        self.records: list[dict] = []

    def emit(self, record: logging.LogRecord) -> None:
        try:
            message = record.getMessage()
        except Exception:  # noqa: BLE001 - a broken log call must not stop the probe
            message = str(record.msg)
        exc = ""
        if record.exc_info:
            exc = logging.Formatter().formatException(record.exc_info)[-3000:]
        self.add(record.levelname, record.name, message, exc)

    def add(self, level: str, logger: str, message: str, exc: str = "") -> None:
        """Keep one record (at most 500)."""
        if len(self.records) < 500:
            self.records.append(
                {"level": level, "logger": logger, "message": message, "exc": exc}
            )


def _plain(value):
    """A JSON-friendly copy (sets, enums, datetimes as text)."""
    return json.loads(json.dumps(value, default=str))


def _recorder_rows(path: str) -> dict[str, int] | None:
    """Rows per entity in the recorder's ``states`` table (None: no database)."""
    if not os.path.exists(path):
        return None
    try:
        con = sqlite3.connect(f"file:{path}?mode=ro", uri=True, timeout=2)
        try:
            rows = con.execute(
                "SELECT m.entity_id, COUNT(*) FROM states s "
                "JOIN states_meta m ON s.metadata_id = m.metadata_id "
                "GROUP BY m.entity_id"
            ).fetchall()
        finally:
            con.close()
    except sqlite3.Error as err:
        return {"<error>": -1, str(err): -1}
    return {entity_id: count for entity_id, count in rows}


async def async_setup(hass: HomeAssistant, config: dict) -> bool:
    """Start writing snapshots and serving requests."""
    collect = _Collect()
    logging.getLogger().addHandler(collect)
    changes: Counter[str] = Counter()
    done: list[dict] = []
    out = hass.config.path(OUT)
    requests = hass.config.path(REQUESTS)
    database = hass.config.path("home-assistant_v2.db")
    os.makedirs(requests, exist_ok=True)

    @callback
    def state_changed(event: Event) -> None:
        changes[event.data["entity_id"]] += 1

    hass.bus.async_listen(EVENT_STATE_CHANGED, state_changed)

    def snapshot() -> dict:
        devices = []
        for d in dr.async_get(hass).devices.values():
            devices.append(
                {
                    "id": d.id,
                    "name": d.name,
                    "identifiers": sorted(list(i) for i in d.identifiers),
                    "via_device_id": d.via_device_id,
                    "manufacturer": d.manufacturer,
                    "model": d.model,
                    "sw_version": d.sw_version,
                    "serial_number": getattr(d, "serial_number", None),
                }
            )
        entities = []
        for e in er.async_get(hass).entities.values():
            entities.append(
                {
                    "entity_id": e.entity_id,
                    "unique_id": e.unique_id,
                    "platform": e.platform,
                    "device_id": e.device_id,
                    "entity_category": e.entity_category,
                    "original_name": e.original_name,
                    "original_device_class": e.original_device_class,
                    "unit_of_measurement": e.unit_of_measurement,
                    "disabled_by": e.disabled_by,
                    "capabilities": e.capabilities,
                }
            )
        states = [
            {
                "entity_id": s.entity_id,
                "state": s.state,
                "attributes": dict(s.attributes),
            }
            for s in hass.states.async_all()
        ]
        config_entries = [
            {"domain": e.domain, "title": e.title, "state": e.state.value}
            for e in hass.config_entries.async_entries()
        ]
        return _plain(
            {
                "version": __version__,
                "config_entries": config_entries,
                "states": states,
                "devices": devices,
                "entities": entities,
                "state_changes": dict(changes),
                "log": collect.records,
                "requests": done,
            }
        )

    def write(data: dict) -> None:
        data["recorder_rows"] = _recorder_rows(database)
        tmp = out + ".tmp"
        with open(tmp, "w", encoding="utf-8") as f:
            json.dump(data, f)
        os.replace(tmp, out)

    def pending() -> list[tuple[str, dict | str]]:
        found = []
        for name in sorted(os.listdir(requests)):
            if not name.endswith(".json"):
                continue
            path = os.path.join(requests, name)
            try:
                with open(path, encoding="utf-8") as f:
                    found.append((path, json.load(f)))
            except (OSError, ValueError) as err:
                found.append((path, str(err)))
        return found

    busy = asyncio.Lock()

    async def tick(_now=None) -> None:
        if busy.locked():
            return
        async with busy:
            try:
                await serve_and_write()
            except Exception as err:  # noqa: BLE001 - reported to the test
                # The probe's own failure (not Home Assistant's): recorded
                # with its traceback, and the next tick tries again.
                collect.add(
                    "PROBE",
                    DOMAIN,
                    f"the probe failed: {err!r}",
                    traceback.format_exc()[-3000:],
                )

    async def serve_and_write() -> None:
        for path, request in await hass.async_add_executor_job(pending):
            base = path[: -len(".json")]
            try:
                if isinstance(request, str):
                    raise ValueError(request)
                await hass.services.async_call(
                    request["domain"],
                    request["service"],
                    request.get("data", {}),
                    blocking=True,
                )
                done.append({"request": os.path.basename(base), "ok": True})
                await hass.async_add_executor_job(os.replace, path, base + ".done")
            except Exception as err:  # noqa: BLE001 - reported to the test
                done.append(
                    {"request": os.path.basename(base), "ok": False, "error": str(err)}
                )
                await hass.async_add_executor_job(os.replace, path, base + ".failed")
        await hass.async_add_executor_job(write, snapshot())

    async_track_time_interval(hass, tick, INTERVAL)
    await tick()
    return True
