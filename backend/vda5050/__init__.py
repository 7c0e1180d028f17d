"""GuideBot as a VDA 5050 master control: vehicles of other makers over MQTT (docs/vda5050.md)."""
