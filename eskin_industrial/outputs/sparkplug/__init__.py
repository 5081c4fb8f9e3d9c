"""The plant side: each bridge as an Eclipse Sparkplug B edge node on MQTT."""
