"""The schedule service over Eclipse Zenoh: key expressions (`keys`), request validation
(`protocol`), the computation behind a reply (`engine`, the per-pose chain on a trained model)
and the worker processes that run it (`workers`), the service's state on disk (`state`), signed
replies (`signing`), the server (`server`), session configuration and default access control
(`session`) and the cell's client (`client`). TLS / mTLS / ACL examples are in `config/`."""

from service.zenoh_service.client import ScheduleClient, ServiceError
from service.zenoh_service.engine import ScheduleEngine
from service.zenoh_service.protocol import RequestError
from service.zenoh_service.server import ScheduleService, ServiceSettings
from service.zenoh_service.session import zenoh_config
from service.zenoh_service.workers import EngineSpec

__all__ = ["EngineSpec", "RequestError", "ScheduleClient", "ScheduleEngine", "ScheduleService", "ServiceError", "ServiceSettings", "zenoh_config"]
