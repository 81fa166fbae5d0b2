// What a confirmation says before a method that moves a device is sent: what moves, where to and how
// far from where it is now (issue #35), from the form's values and the device's latest osd.

const R = 6378137; // m, WGS84 equatorial radius (the simulator's flat-earth model uses the same)

function fmt(v, digits = 1) {
  return typeof v === "number" && Number.isFinite(v) ? v.toFixed(digits).replace(/\.0+$/, "") : "?";
}

/** Distance (m) and compass direction from a to b, or null without both positions. */
function leg(from, lat, lon) {
  if (!from || typeof from.latitude !== "number" || typeof lat !== "number" || typeof lon !== "number") return null;
  const north = ((lat - from.latitude) * Math.PI / 180) * R;
  const east = ((lon - from.longitude) * Math.PI / 180) * R * Math.cos(from.latitude * Math.PI / 180);
  const dist = Math.hypot(north, east);
  const dirs = ["north", "north-east", "east", "south-east", "south", "south-west", "west", "north-west"];
  const bearing = (Math.atan2(east, north) * 180 / Math.PI + 360) % 360;
  return { dist, dir: dirs[Math.round(bearing / 45) % 8] };
}

function far(from, lat, lon) {
  const l = leg(from, lat, lon);
  return l ? `, ${fmt(l.dist, 0)} m ${l.dir} of where it is now` : "";
}

/** One sentence (or two) saying what ``method`` with ``value`` moves on device ``sn``. */
export function describe(method, sn, value, osd) {
  const v = value || {};
  switch (method) {
    case "takeoff_to_point":
      return `${sn} takes off, climbs to ${fmt(v.security_takeoff_height)} m above the take-off point, then flies to ` +
        `${fmt(v.target_latitude, 6)}, ${fmt(v.target_longitude, 6)} at ${fmt(v.target_height)} m (WGS84 altitude)` +
        `${far(osd, v.target_latitude, v.target_longitude)}, at most ${fmt(v.max_speed)} m/s; return-home altitude ${fmt(v.rth_altitude)} m.`;
    case "fly_to_point": {
      const points = Array.isArray(v.points) ? v.points : [];
      const p = points[0] || {};
      return `${sn} flies to ${points.length} point(s), the first ${fmt(p.latitude, 6)}, ${fmt(p.longitude, 6)} at ` +
        `${fmt(p.height)} m${far(osd, p.latitude, p.longitude)}, at most ${fmt(v.max_speed)} m/s.`;
    }
    case "return_home":
      return `${sn} flies home (its last take-off point) and lands${osd && typeof osd.home_distance === "number" ? `: ${fmt(osd.home_distance, 0)} m away` : ""}.`;
    case "camera_aim":
      return `The gimbal of ${sn} turns so that point (${fmt(v.x, 2)}, ${fmt(v.y, 2)}) of the ${v.camera_type || ""} camera's picture ` +
        `(0..1 from the top left) comes to its centre.`;
    case "camera_screen_drag":
      return `The gimbal of ${sn} turns at ${fmt(v.pitch_speed)} °/s in pitch and ${v.locked ? "0 (locked)" : fmt(v.yaw_speed)} °/s in yaw.`;
    case "gimbal_reset":
      return `The gimbal of ${sn} turns: ${["recentre", "down", "recentre pan", "pitch down"][v.reset_mode] || `reset mode ${v.reset_mode}`}.`;
    case "flighttask_execute":
    case "flighttask_recovery":
      return `${sn} flies wayline task ${v.flight_id || "?"} (its route, from where it is now).`;
    case "drc_mode_enter":
      return `Live control starts on the broker ${(v.mqtt_broker || {}).address || "?"}: sticks sent there move the aircraft ` +
        `(and gimbals whose authority the gateway holds) until drc_mode_exit.`;
    default:
      return `${method} on ${sn} moves the device.`;
  }
}
