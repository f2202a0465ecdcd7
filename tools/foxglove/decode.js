#!/usr/bin/env node
// Decodes an mps_runner run file (MCAP, protobuf) the way the Foxglove and Lichtblick viewers do,
// and prints a JSON summary of what a viewer user sees: per channel the message count and the
// top-level fields, the shape of the metrics maps, the values of plot paths evaluated with the
// viewers' message-path rules, and the foxglove.PointCloud fields the 3D panel can colour by.
//
//   node tools/foxglove/decode.js FILE [--series] [--path PATH]...
//
//   --series     list every message's value for each plot path (log time, value, IEEE-754 bits)
//   --path PATH  evaluate an extra message path (e.g. '/summary.checkpoints[:].time_s')
//
// Exit status: 0 when every channel and every message decodes, 1 when something does not decode
// (the JSON says what), 2 when the file cannot be read at all (message on stderr).
//
// What is copied from the viewers (Foxglove's @mcap/support parseProtobufSchema and Studio's
// parseChannelOptions; Lichtblick uses the same code):
//   - the type: protobufjs `Root.fromDescriptor(FileDescriptorSet.decode(schema.data))`,
//     `root.resolveAll()`, `root.lookupType(schema.name)`;
//   - google.protobuf.Timestamp and Duration objects become {sec, nsec} (Studio's fixTimeType);
//   - each message: `type.toObject(type.decode(bytes), { defaults: true, longs: BigInt })`, so
//     64-bit integers arrive as bigint, enums as numbers, bytes as Uint8Array and a protobuf `map`
//     as a list of {key, value} entries (protobufjs builds no map field from a descriptor);
//   - the datatypes the panels use for autocomplete and plot checks (protobufDefinitionsToDatatypes);
//   - message paths: the grammar of @lichtblick/message-path (topic, `.field`, `[i]`, `[a:b]`, `[:]`,
//     `{path==value}` filters) and simpleGetMessagePathDataItems / filterMatches for evaluation.
"use strict";

const fs = require("fs");
const nodePath = require("path");
const protobuf = require("protobufjs");
const { FileDescriptorSet } = require("protobufjs/ext/descriptor");
const { McapIndexedReader, McapStreamReader } = require("@mcap/core");
const { loadDecompressHandlers } = require("@mcap/support");

const TO_OBJECT_OPTIONS = { defaults: true, longs: BigInt };

// foxglove.PackedElementField.NumericType: value -> [name, size in bytes, DataView getter]
const NUMERIC_TYPES = {
  1: ["UINT8", 1, "getUint8"],
  2: ["INT8", 1, "getInt8"],
  3: ["UINT16", 2, "getUint16"],
  4: ["INT16", 2, "getInt16"],
  5: ["UINT32", 4, "getUint32"],
  6: ["INT32", 4, "getInt32"],
  7: ["FLOAT32", 4, "getFloat32"],
  8: ["FLOAT64", 8, "getFloat64"],
};

// Types the Plot panel accepts at the end of a path (plotableRosTypes).
const PLOTABLE = new Set([
  "bool", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64",
  "float32", "float64", "time", "duration", "string",
]);

function usage(message) {
  process.stderr.write(`${message}\nusage: node decode.js FILE [--series] [--path PATH]...\n`);
  process.exit(2);
}

// ---------------------------------------------------------------------------------------------
// Schema -> deserializer, as parseProtobufSchema (+ Studio's parseChannelOptions) does it.

function protobufScalarToRosPrimitive(type) {
  switch (type) {
    case "double": return "float64";
    case "float": return "float32";
    case "int32": case "sint32": case "sfixed32": return "int32";
    case "uint32": case "fixed32": return "uint32";
    case "int64": case "sint64": case "sfixed64": return "int64";
    case "uint64": case "fixed64": return "uint64";
    case "bool": return "bool";
    case "string": return "string";
  }
  throw new Error(`Expected protobuf scalar type, got ${type}`);
}

const stripLeadingDot = (name) => name.replace(/^\./, "");

/** protobufDefinitionsToDatatypes: datatype name -> [{name, type, isArray, isComplex}]. */
function protobufDefinitionsToDatatypes(datatypes, type) {
  const definitions = [];
  datatypes.set(stripLeadingDot(type.fullName), definitions);
  for (const field of type.fieldsArray) {
    if (field.resolvedType instanceof protobuf.Enum) {
      definitions.push({ name: field.name, type: "int32", isArray: field.repeated });
    } else if (field.resolvedType) {
      const fullName = stripLeadingDot(field.resolvedType.fullName);
      definitions.push({ name: field.name, type: fullName, isComplex: true, isArray: field.repeated });
      if (!datatypes.has(fullName)) {
        protobufDefinitionsToDatatypes(datatypes, field.resolvedType);
      }
    } else if (field.type === "bytes") {
      definitions.push({ name: field.name, type: "uint8", isArray: true });
    } else {
      definitions.push({
        name: field.name,
        type: protobufScalarToRosPrimitive(field.type),
        isArray: field.repeated,
      });
    }
  }
}

/** Studio's fixTimeType: Timestamp/Duration objects as {sec, nsec}. */
function fixTimeType(type) {
  if (!type || !(type instanceof protobuf.Type)) {
    return;
  }
  type.setup();
  const prevToObject = type.toObject;
  type.toObject = (message, options) => {
    const result = prevToObject.call(type, message, options);
    const { seconds, nanos } = result;
    if (typeof seconds !== "bigint" || typeof nanos !== "number") {
      return result;
    }
    if (seconds > BigInt(Number.MAX_SAFE_INTEGER)) {
      throw new Error(`Timestamps with seconds greater than 2^53-1 are not supported`);
    }
    return { sec: Number(seconds), nsec: nanos };
  };
}

function parseProtobufChannel(channel, schema) {
  if (channel.messageEncoding !== "protobuf") {
    throw new Error(`message encoding ${channel.messageEncoding}, expected protobuf`);
  }
  if (!schema || schema.encoding !== "protobuf") {
    throw new Error(`schema encoding ${schema ? schema.encoding : "(none)"}, expected protobuf`);
  }
  const root = protobuf.Root.fromDescriptor(FileDescriptorSet.decode(schema.data));
  root.resolveAll();
  const rootType = root.lookupType(schema.name);
  fixTimeType(rootType.lookup(".google.protobuf.Timestamp"));
  fixTimeType(rootType.lookup(".google.protobuf.Duration"));
  const datatypes = new Map();
  protobufDefinitionsToDatatypes(datatypes, rootType);
  if (!datatypes.has(schema.name)) {
    throw new Error(`Protobuf schema does not contain an entry for '${schema.name}'`);
  }
  const deserialize = (data) =>
    rootType.toObject(
      rootType.decode(new Uint8Array(data.buffer, data.byteOffset, data.byteLength)),
      TO_OBJECT_OPTIONS,
    );
  return { rootType, datatypes, deserialize };
}

// ---------------------------------------------------------------------------------------------
// Message paths: the @lichtblick/message-path grammar (the subset without variables/modifiers).

function parseMessagePath(text) {
  let i = 0;
  const fail = (why) => {
    throw new Error(`bad message path ${JSON.stringify(text)} at ${i}: ${why}`);
  };
  const idChar = (c) => c !== undefined && /[a-zA-Z0-9_-]/.test(c);
  const readId = () => {
    const start = i;
    while (idChar(text[i])) i++;
    return text.slice(start, i);
  };
  const readInteger = () => {
    const m = /^-?[0-9]+/.exec(text.slice(i));
    if (!m) return undefined;
    i += m[0].length;
    return BigInt(m[0]);
  };
  const readValue = () => {
    const q = text[i];
    if (q === '"' || q === "'") {
      const end = text.indexOf(q, i + 1);
      if (end < 0) fail("unterminated string");
      const value = text.slice(i + 1, end);
      i = end + 1;
      return value;
    }
    if (text.startsWith("true", i)) { i += 4; return true; }
    if (text.startsWith("false", i)) { i += 5; return false; }
    const n = readInteger();
    if (n === undefined) fail("expected an integer, a string, true or false");
    return n;
  };
  const readFilter = () => {
    i++; // {
    const path = [readId()];
    while (text[i] === ".") { i++; path.push(readId()); }
    const op = ["==", "!=", ">=", "<=", ">", "<"].find((o) => text.startsWith(o, i));
    if (!op) fail("expected a comparison operator");
    i += op.length;
    const value = readValue();
    if (text[i] !== "}") fail("expected }");
    i++;
    return { type: "filter", path, operator: op, value };
  };
  const readSlice = () => {
    i++; // [
    const start = readInteger();
    if (text[i] === "]") {
      i++;
      if (start === undefined) fail("empty index");
      return { type: "slice", start: Number(start), end: Number(start) };
    }
    if (text[i] !== ":") fail("expected : or ]");
    i++;
    const end = readInteger();
    if (text[i] !== "]") fail("expected ]");
    i++;
    return {
      type: "slice",
      start: start === undefined ? 0 : Number(start),
      end: end === undefined ? Infinity : Number(end),
    };
  };

  if (text[0] !== "/") fail("a path starts with its topic");
  let topicName = "";
  while (text[i] === "/") {
    i++;
    topicName += "/" + readId();
  }
  const messagePath = [];
  while (i < text.length) {
    if (text[i] === ".") {
      i++;
      if (text[i] === "@") fail("modifiers are not supported here");
      const name = readId();
      if (!name) fail("expected a field name");
      messagePath.push({ type: "name", name });
      if (text[i] === "[") messagePath.push(readSlice());
      if (text[i] === "{") messagePath.push(readFilter());
    } else if (text[i] === "{") {
      messagePath.push(readFilter());
    } else {
      fail("expected . or {");
    }
  }
  return { topicName, messagePath };
}

function filterMatches(filter, value) {
  if (filter.value == undefined) return false;
  let current = value;
  for (const name of filter.path) {
    if (typeof current !== "object" || current == undefined) return false;
    current = current[name];
    if (current == undefined) return false;
  }
  /* eslint-disable eqeqeq */
  switch (filter.operator) {
    case "==": return current == filter.value;
    case "!=": return current != filter.value;
    case ">=": return current >= filter.value;
    case "<=": return current <= filter.value;
    case ">": return current > filter.value;
    case "<": return current < filter.value;
    default: return false;
  }
  /* eslint-enable eqeqeq */
}

/** simpleGetMessagePathDataItems: every item the path picks out of one message. */
function messagePathItems(message, path) {
  const results = [];
  const traverse = (value, index) => {
    const part = path.messagePath[index];
    if (part === undefined) {
      results.push(value);
      return;
    }
    if (value == undefined) return;
    switch (part.type) {
      case "slice":
        if (!Array.isArray(value) && !ArrayBuffer.isView(value)) return;
        for (let k = part.start; k < value.length && k <= part.end; k++) traverse(value[k], index + 1);
        return;
      case "filter":
        if (filterMatches(part, value)) traverse(value, index + 1);
        return;
      case "name":
        if (typeof value !== "object") return;
        traverse(value[part.name], index + 1);
        return;
    }
  };
  traverse(message, 0);
  return results;
}

/**
 * The datatype a path ends on, as the panels' path checks see it: a slice steps into the array's
 * element type (`[:]` and `[a:b]` may give several values per message, `[i]` one), a filter keeps
 * the type. Returns {type, multi, plotable} or {error}.
 */
function pathDatatype(path, rootName, datatypes) {
  let type = rootName;
  let isArray = false;
  let multi = false;
  for (const part of path.messagePath) {
    if (part.type === "name") {
      if (isArray) return { error: `.${part.name} applied to an array (add [:] or [i])` };
      const defs = datatypes.get(type);
      const def = defs && defs.find((d) => d.name === part.name);
      if (!def) return { error: `${type} has no field ${part.name}` };
      type = def.type;
      isArray = Boolean(def.isArray);
    } else if (part.type === "slice") {
      if (!isArray) return { error: "slice on a value that is not an array" };
      isArray = false;
      if (part.start !== part.end) multi = true;
    }
  }
  if (isArray) return { error: `the path ends on an array (${type}[])` };
  return { type, multi, plotable: PLOTABLE.has(type) };
}

// ---------------------------------------------------------------------------------------------
// Output helpers.

function jsType(value) {
  if (value === undefined) return "undefined";
  if (value === null) return "null";
  if (Array.isArray(value)) return "array";
  if (ArrayBuffer.isView(value)) return "bytes";
  return typeof value;
}

function f64Bits(x) {
  const view = new DataView(new ArrayBuffer(8));
  view.setFloat64(0, x, true);
  return view.getBigUint64(0, true).toString(16).padStart(16, "0");
}

function mapShape(value) {
  if (Array.isArray(value)) {
    const entries = value.every(
      (e) => e && typeof e === "object" && Object.keys(e).sort().join(",") === "key,value",
    );
    return entries ? "array of {key, value} entries" : "array";
  }
  if (value && typeof value === "object") return "object keyed by name";
  return jsType(value);
}

/** Installed version of a dependency (its package.json, read from node_modules). */
function packageVersion(name) {
  const file = nodePath.join(__dirname, "node_modules", name, "package.json");
  return JSON.parse(fs.readFileSync(file, "utf8")).version;
}

function toJson(value) {
  return JSON.stringify(
    value,
    (_, v) => (typeof v === "bigint" ? v.toString() : v),
    2,
  );
}

// ---------------------------------------------------------------------------------------------
// Reading the file: the indexed reader as the viewers use for a file with a summary, the streaming
// reader for a file without one (a killed run's .partial).

async function readRun(bytes) {
  const decompressHandlers = await loadDecompressHandlers();
  try {
    const readable = {
      size: async () => BigInt(bytes.length),
      read: async (offset, size) => bytes.subarray(Number(offset), Number(offset + size)),
    };
    const reader = await McapIndexedReader.Initialize({ readable, decompressHandlers });
    const messages = [];
    for await (const m of reader.readMessages({ validateCrcs: true })) messages.push(m);
    const counts = reader.statistics
      ? new Map([...reader.statistics.channelMessageCounts].map(([k, v]) => [k, Number(v)]))
      : undefined;
    return {
      reader: "indexed",
      profile: reader.header.profile,
      channels: reader.channelsById,
      schemas: reader.schemasById,
      messages,
      statisticsCounts: counts,
      indexError: undefined,
    };
  } catch (indexError) {
    const stream = new McapStreamReader({ decompressHandlers, validateCrcs: true });
    stream.append(bytes);
    const channels = new Map();
    const schemas = new Map();
    const messages = [];
    let profile;
    let streamError;
    try {
      for (let r; (r = stream.nextRecord()); ) {
        if (r.type === "Header") profile = r.profile;
        else if (r.type === "Schema") schemas.set(r.id, r);
        else if (r.type === "Channel") channels.set(r.id, r);
        else if (r.type === "Message") messages.push(r);
      }
    } catch (e) {
      streamError = String(e && e.message ? e.message : e);
    }
    if (channels.size === 0) throw indexError;
    return {
      reader: "stream",
      profile,
      channels,
      schemas,
      messages,
      statisticsCounts: undefined,
      indexError: String(indexError && indexError.message ? indexError.message : indexError),
      streamError,
    };
  }
}

// ---------------------------------------------------------------------------------------------

function pointCloudReport(clouds) {
  const last = clouds[clouds.length - 1];
  if (!last) return { messages: 0 };
  const m = last.message;
  const stride = m.point_stride;
  const data = m.data;
  const problems = [];
  if (!stride) problems.push("point_stride is 0");
  if (stride && data.length % stride !== 0) {
    problems.push(`data length ${data.length} is not a multiple of point_stride ${stride}`);
  }
  const fields = m.fields.map((f) => {
    const known = NUMERIC_TYPES[f.type];
    if (!known) problems.push(`field ${f.name}: unknown numeric type ${f.type}`);
    else if (f.offset + known[1] > stride) problems.push(`field ${f.name} runs past point_stride`);
    return { name: f.name, offset: f.offset, type: f.type, type_name: known ? known[0] : null };
  });
  for (const required of ["x", "y", "z"]) {
    if (!fields.some((f) => f.name === required)) problems.push(`no ${required} field`);
  }
  // Ranges of every field in the last cloud, read as the 3D panel's field readers do.
  const count = stride ? Math.trunc(data.length / stride) : 0;
  const view = new DataView(data.buffer, data.byteOffset, data.byteLength);
  const ranges = {};
  for (const f of fields) {
    const known = NUMERIC_TYPES[f.type];
    if (!known || f.offset + known[1] > stride) continue;
    let min = Infinity;
    let max = -Infinity;
    let finite = true;
    for (let p = 0; p < count; p++) {
      const v = known[1] === 1 ? view[known[2]](p * stride + f.offset) : view[known[2]](p * stride + f.offset, true);
      if (!Number.isFinite(v)) finite = false;
      if (v < min) min = v;
      if (v > max) max = v;
    }
    ranges[f.name] = { min, max, all_finite: finite };
  }
  // Fields in the same order and layout in every cloud of the run.
  const layout = (msg) => msg.fields.map((f) => `${f.name}@${f.offset}:${f.type}`).join(",") + `/${msg.point_stride}`;
  const layouts = new Set(clouds.map((c) => layout(c.message)));
  if (layouts.size !== 1) problems.push(`${layouts.size} different field layouts across the run`);
  return {
    messages: clouds.length,
    frame_id: m.frame_id,
    timestamp: m.timestamp,
    pose: m.pose,
    point_stride: stride,
    points_in_last_cloud: count,
    fields,
    colour_fields: fields.filter((f) => !["x", "y", "z"].includes(f.name)).map((f) => f.name),
    ranges_in_last_cloud: ranges,
    same_layout_in_every_cloud: layouts.size === 1,
    problems,
  };
}

async function main() {
  const args = process.argv.slice(2);
  let file;
  let series = false;
  const extraPaths = [];
  for (let k = 0; k < args.length; k++) {
    if (args[k] === "--series") series = true;
    else if (args[k] === "--path") {
      if (k + 1 >= args.length) usage("--path needs a message path");
      extraPaths.push(args[++k]);
    } else if (args[k].startsWith("--")) usage(`unknown option ${args[k]}`);
    else if (file === undefined) file = args[k];
    else usage(`unexpected argument ${args[k]}`);
  }
  if (file === undefined) usage("no run file given");

  let bytes;
  try {
    bytes = fs.readFileSync(file);
  } catch (e) {
    process.stderr.write(`cannot read ${file}: ${e.message}\n`);
    process.exit(2);
  }
  let run;
  try {
    run = await readRun(new Uint8Array(bytes.buffer, bytes.byteOffset, bytes.byteLength));
  } catch (e) {
    process.stderr.write(`${file} is not a readable MCAP file: ${e.message}\n`);
    process.exit(2);
  }

  // Channels -> deserializers.
  const parsed = new Map();
  const channels = [];
  for (const [id, channel] of [...run.channels].sort((a, b) => a[0] - b[0])) {
    const schema = run.schemas.get(channel.schemaId);
    const entry = {
      topic: channel.topic,
      schema: schema ? schema.name : null,
      schema_encoding: schema ? schema.encoding : null,
      message_encoding: channel.messageEncoding,
      schema_error: null,
      messages: 0,
      decoded: 0,
      decode_errors: [],
      statistics_count: run.statisticsCounts ? run.statisticsCounts.get(id) ?? 0 : null,
      fields: [],
      field_types: {},
    };
    try {
      const p = parseProtobufChannel(channel, schema);
      parsed.set(id, p);
      for (const def of p.datatypes.get(schema.name)) {
        entry.field_types[def.name] = def.type + (def.isArray ? "[]" : "");
      }
    } catch (e) {
      entry.schema_error = String(e.message || e);
    }
    channels.push([id, entry]);
  }
  const byId = new Map(channels);

  // Every message, decoded.
  const decodedByTopic = new Map();
  for (const m of run.messages) {
    const entry = byId.get(m.channelId);
    if (!entry) continue;
    entry.messages++;
    const p = parsed.get(m.channelId);
    if (!p) continue;
    try {
      const message = p.deserialize(m.data);
      entry.decoded++;
      if (!decodedByTopic.has(entry.topic)) decodedByTopic.set(entry.topic, []);
      decodedByTopic.get(entry.topic).push({ logTime: m.logTime, message });
    } catch (e) {
      if (entry.decode_errors.length < 5) {
        entry.decode_errors.push(`sequence ${m.sequence}: ${e.message || e}`);
      }
    }
  }
  for (const [, entry] of channels) {
    const first = (decodedByTopic.get(entry.topic) || [])[0];
    if (first) {
      // Top-level field names of the decoded object (with defaults: every field of the schema),
      // and for each the schema datatype and what JavaScript value the panels receive.
      entry.fields = Object.keys(first.message);
      for (const [k, v] of Object.entries(first.message)) {
        entry.field_types[k] = `${entry.field_types[k]} -> ${jsType(v)}`;
      }
    }
  }

  // Maps (repeated XxxEntry {key, value} types from protobuf `map<,>` fields).
  const maps = {};
  const pathsToCheck = [];
  for (const [id, entry] of channels) {
    const p = parsed.get(id);
    if (!p) continue;
    const defs = p.datatypes.get(entry.schema);
    for (const def of defs) {
      const scalar = !def.isArray && !def.isComplex && PLOTABLE.has(def.type) && def.type !== "string";
      if (scalar) pathsToCheck.push(`${entry.topic}.${def.name}`);
      if (!(def.isComplex && def.isArray)) continue;
      const entryType = p.rootType.lookupTypeOrEnum(def.type);
      const entryDefs = p.datatypes.get(def.type) || [];
      const isMapEntry = Boolean(entryType.options && entryType.options.map_entry) ||
        (entryDefs.length === 2 && entryDefs[0].name === "key" && entryDefs[1].name === "value");
      if (!isMapEntry) continue;
      const messages = decodedByTopic.get(entry.topic) || [];
      const keys = [];
      for (const { message } of messages) {
        for (const e of message[def.name] || []) if (!keys.includes(e.key)) keys.push(e.key);
      }
      const first = messages[0] ? messages[0].message[def.name] : undefined;
      maps[`${entry.topic}.${def.name}`] = {
        proto: `map<${entryDefs[0] && entryDefs[0].type}, ${entryDefs[1] && entryDefs[1].type}>`,
        descriptor_map_entry_option: Boolean(entryType.options && entryType.options.map_entry),
        decoded_shape: mapShape(first),
        datatype: `${def.type}[]`,
        keys,
        sample: Array.isArray(first) ? first.slice(0, 3) : first,
      };
      for (const key of keys) {
        pathsToCheck.push(`${entry.topic}.${def.name}.${key}`);
        pathsToCheck.push(`${entry.topic}.${def.name}[:]{key=="${key}"}.value`);
      }
    }
  }
  pathsToCheck.push(...extraPaths);

  // Plot paths, evaluated on every message of their topic.
  const topicRoots = new Map(channels.map(([id, e]) => [e.topic, { id, schema: e.schema }]));
  const plotPaths = [];
  for (const text of pathsToCheck) {
    const out = { path: text };
    let path;
    try {
      path = parseMessagePath(text);
    } catch (e) {
      plotPaths.push({ ...out, resolves: false, error: e.message });
      continue;
    }
    const root = topicRoots.get(path.topicName);
    const p = root && parsed.get(root.id);
    if (!p) {
      plotPaths.push({ ...out, resolves: false, error: `no decodable topic ${path.topicName}` });
      continue;
    }
    const dt = pathDatatype(path, root.schema, p.datatypes);
    const messages = decodedByTopic.get(path.topicName) || [];
    let oneNumber = 0;
    const kinds = new Set();
    const values = [];
    for (const { logTime, message } of messages) {
      const items = messagePathItems(message, path);
      for (const item of items) kinds.add(jsType(item));
      if (items.length === 1 && typeof items[0] === "number") {
        oneNumber++;
        values.push([logTime.toString(), items[0], f64Bits(items[0])]);
      } else {
        values.push([logTime.toString(), items.length === 1 ? items[0] : items, null]);
      }
    }
    // Resolves: the path checks out against the datatypes, ends on a plottable type, and picks
    // exactly one JavaScript number out of every message of its topic.
    out.resolves = messages.length > 0 && oneNumber === messages.length && !dt.error && dt.plotable;
    out.datatype = dt.error ? null : dt.type;
    if (dt.error) out.error = dt.error;
    else if (!dt.plotable) out.error = `${dt.type} is not a plottable type`;
    else if (kinds.has("bigint")) {
      out.error = "values arrive as bigint (64-bit integer): the Plot panel converts them with Number()";
    } else if (!out.resolves && messages.length > 0) {
      const counts = values.map((v) => (v[2] !== null ? 1 : Array.isArray(v[1]) ? v[1].length : 1));
      out.error = counts.some((c) => c > 1)
        ? "several values in a message (the Plot panel draws each)"
        : "no number in some messages";
    }
    out.messages = messages.length;
    out.numbers = oneNumber;
    out.items = [...kinds].join(",");
    if (values.length) {
      out.first = values[0][1];
      out.last = values[values.length - 1][1];
    }
    if (series) out.series = values;
    plotPaths.push(out);
  }

  const summary = {
    file,
    decoder: {
      protobufjs: packageVersion("protobufjs"),
      "@mcap/core": packageVersion("@mcap/core"),
      "@mcap/support": packageVersion("@mcap/support"),
      type_from: "protobuf.Root.fromDescriptor(FileDescriptorSet.decode(schema.data)).lookupType(schema.name)",
      to_object_options: "{ defaults: true, longs: BigInt }",
      reader: run.reader,
    },
    profile: run.profile,
    ok: true,
    channels: Object.fromEntries(channels.map(([, e]) => [e.topic, e])),
    maps,
    plot_paths: plotPaths,
    point_cloud: {},
  };
  if (run.indexError) summary.decoder.index_error = run.indexError;
  if (run.streamError) summary.decoder.stream_error = run.streamError;
  for (const [, e] of channels) {
    if (e.schema === "foxglove.PointCloud") {
      summary.point_cloud[e.topic] = pointCloudReport(decodedByTopic.get(e.topic) || []);
    }
  }
  for (const [, e] of channels) {
    if (e.schema_error || e.decode_errors.length || e.decoded !== e.messages) summary.ok = false;
    if (e.statistics_count !== null && e.statistics_count !== e.messages) summary.ok = false;
  }
  for (const pc of Object.values(summary.point_cloud)) if (pc.problems && pc.problems.length) summary.ok = false;
  if (run.streamError) summary.ok = false;
  process.stdout.write(toJson(summary) + "\n");
  process.exit(summary.ok ? 0 : 1);
}

main().catch((e) => {
  process.stderr.write(`decode.js: ${e && e.stack ? e.stack : e}\n`);
  process.exit(2);
});
