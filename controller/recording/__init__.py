"""Run recordings (MCAP with Foxglove's schemas) and their replay as video or contact sheet."""
