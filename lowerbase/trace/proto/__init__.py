"""The seed's protobuf messages (generated from trace.proto, see lowerbase.trace.protogen)."""
