"""Run recordings (MCAP through the Foxglove SDK) and their replay as video or contact sheet."""
