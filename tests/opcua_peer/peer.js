// An OPC UA client of node-opcua (an independent stack), driven by the tests: one JSON
// request a line on stdin, one JSON answer a line on stdout ({"id": N, "ok": true, ...}
// or {"id": N, "ok": false, "error": "...", "status": "BadXxx"}), and what a
// subscription delivers as lines of their own ({"event": "data" | "alarm", ...}).
// tests/helpers/opcua.py starts it (node peer.js) and speaks to it.
"use strict";

const readline = require("readline");
const path = require("path");
const fs = require("fs");
const {
    OPCUAClient, MessageSecurityMode, SecurityPolicy, AttributeIds, ClientSubscription, ClientMonitoredItem,
    TimestampsToReturn, DataType, BrowseDirection, NodeClass, UserTokenType, constructEventFilter, coerceNodeId,
    StatusCodes, makeBrowsePath,
} = require("node-opcua-client");
const { OPCUACertificateManager } = require("node-opcua-certificate-manager");

let client = null;
let session = null;
let subscription = null;

function out(obj) {
    process.stdout.write(JSON.stringify(obj) + "\n");
}

function jsonValue(v) {
    if (v === null || v === undefined) return null;
    if (typeof v === "bigint") return Number(v);
    if (Buffer.isBuffer(v)) return { base64: v.toString("base64") };
    if (ArrayBuffer.isView(v)) return Array.from(v).map(jsonValue);
    if (Array.isArray(v)) return v.map(jsonValue);
    if (typeof v === "object") {
        if (v.constructor && v.constructor.name === "LocalizedText") return v.text;
        if (v.constructor && v.constructor.name === "NodeId") return v.toString();
        if (v.constructor && v.constructor.name === "QualifiedName") return v.toString();
        if (typeof v.toJSON === "function") return v.toJSON();
        if (Array.isArray(v)) return v.map(jsonValue);
        if (v[0] !== undefined && v[1] !== undefined && v.length === 2) return [v[0], v[1]]; // UInt64 as [hi, lo]
        return String(v);
    }
    if (typeof v === "number" && !Number.isFinite(v)) return String(v);
    return v;
}

function dataValue(dv) {
    const value = dv.value ? dv.value.value : null;
    return {
        value: dv.value && dv.value.dataType === DataType.UInt64 && Array.isArray(value)
            ? value[0] * 4294967296 + value[1] : jsonValue(value),
        dataType: dv.value ? DataType[dv.value.dataType] : null,
        dimensions: dv.value && dv.value.dimensions ? dv.value.dimensions : null,
        status: dv.statusCode.name,
        code: dv.statusCode.value >>> 0,
        sourceTimestamp: dv.sourceTimestamp ? dv.sourceTimestamp.getTime() : null,
        sourcePicoseconds: dv.sourcePicoseconds || 0,
        serverTimestamp: dv.serverTimestamp ? dv.serverTimestamp.getTime() : null,
    };
}

async function connect(req) {
    const mode = MessageSecurityMode[req.mode || "None"];
    const policy = SecurityPolicy[req.policy || "None"];
    const options = {
        applicationName: "eskin-industrial test peer",
        applicationUri: req.applicationUri || "urn:eskin-industrial:test-peer",
        securityMode: mode,
        securityPolicy: policy,
        endpointMustExist: false,
        keepSessionAlive: false,
        connectionStrategy: { maxRetry: 0, initialDelay: 100, maxDelay: 200 },
        requestedSessionTimeout: req.sessionTimeoutMs || 60000,
        defaultSecureTokenLifetime: 600000,
    };
    if (req.pki) {
        const manager = new OPCUACertificateManager({ rootFolder: req.pki, automaticallyAcceptUnknownCertificate: true });
        await manager.initialize();
        options.clientCertificateManager = manager;
        options.certificateFile = path.join(req.pki, "own", "certs", "client_certificate.pem");
        options.privateKeyFile = path.join(req.pki, "own", "private", "private_key.pem");
    }
    client = OPCUAClient.create(options);
    await client.connect(req.url);
    const identity = req.user
        ? { type: UserTokenType.UserName, userName: req.user, password: req.password }
        : { type: UserTokenType.Anonymous };
    try {
        session = await client.createSession(identity);
    } catch (err) {
        await client.disconnect();
        client = null;
        throw err;
    }
    return { certificateFile: options.certificateFile || null };
}

async function browseTree(nodeId, prefix, outList, depth) {
    const result = await session.browse({
        nodeId, referenceTypeId: "HierarchicalReferences", includeSubtypes: true,
        browseDirection: BrowseDirection.Forward, nodeClassMask: 0, resultMask: 63,
    });
    for (const ref of result.references || []) {
        const name = ref.browseName.name;
        const p = prefix ? prefix + "/" + name : name;
        const item = {
            path: p, nodeId: ref.nodeId.toString(), nodeClass: NodeClass[ref.nodeClass],
            typeDefinition: ref.typeDefinition ? ref.typeDefinition.toString() : null,
            browseName: ref.browseName.toString(), displayName: ref.displayName.text,
        };
        outList.push(item);
        if (ref.nodeClass === NodeClass.Variable) {
            const attrs = await session.read([
                { nodeId: ref.nodeId, attributeId: AttributeIds.Value },
                { nodeId: ref.nodeId, attributeId: AttributeIds.DataType },
                { nodeId: ref.nodeId, attributeId: AttributeIds.ValueRank },
                { nodeId: ref.nodeId, attributeId: AttributeIds.ArrayDimensions },
                { nodeId: ref.nodeId, attributeId: AttributeIds.Description },
                { nodeId: ref.nodeId, attributeId: AttributeIds.AccessLevel },
                { nodeId: ref.nodeId, attributeId: AttributeIds.UserAccessLevel },
            ]);
            Object.assign(item, dataValue(attrs[0]));
            item.dataTypeId = attrs[1].value.value ? attrs[1].value.value.toString() : null;
            item.valueRank = attrs[2].value.value;
            item.arrayDimensions = attrs[3].value.value ? Array.from(attrs[3].value.value) : null;
            item.description = attrs[4].value.value ? attrs[4].value.value.text : null;
            item.accessLevel = attrs[5].value.value;
            item.userAccessLevel = attrs[6].value.value;
        }
        if (depth < 8 && (ref.nodeClass === NodeClass.Object || ref.nodeClass === NodeClass.Variable)) {
            await browseTree(ref.nodeId, p, outList, depth + 1);
        }
    }
}

async function ensureSubscription(req) {
    if (subscription) return subscription;
    subscription = ClientSubscription.create(session, {
        requestedPublishingInterval: req.publishingInterval || 20,
        requestedMaxKeepAliveCount: 20,
        requestedLifetimeCount: 600,
        maxNotificationsPerPublish: 1000,
        publishingEnabled: true,
        priority: 10,
    });
    await new Promise((resolve, reject) => {
        subscription.once("started", resolve);
        subscription.once("internal_error", reject);
    });
    return subscription;
}

const ALARM_FIELDS = ["EventId", "EventType", "SourceNode", "SourceName", "Time", "ReceiveTime", "Message", "Severity",
    "ConditionName", "Retain", "ActiveState", "ActiveState.Id", "AckedState", "AckedState.Id", "EnabledState.Id",
    "Comment", "ConditionId", "1:ScoreA", "1:ScoreB", "1:ScoreNames", "1:Delay", "1:SensorTime", "1:SlipEvents"];

async function handle(req) {
    switch (req.op) {
        case "connect":
            return await connect(req);
        case "endpoints": {
            const c = OPCUAClient.create({ endpointMustExist: false, connectionStrategy: { maxRetry: 0 } });
            await c.connect(req.url);
            const eps = await c.getEndpoints();
            await c.disconnect();
            return {
                endpoints: eps.map((e) => ({
                    policy: e.securityPolicyUri.split("#")[1], mode: MessageSecurityMode[e.securityMode],
                    tokens: (e.userIdentityTokens || []).map((t) => UserTokenType[t.tokenType]),
                })),
            };
        }
        case "namespace": {
            const dv = await session.read({ nodeId: "ns=0;i=2255", attributeId: AttributeIds.Value });
            return { index: dv.value.value.indexOf(req.uri) };
        }
        case "browse": {
            const list = [];
            await browseTree(coerceNodeId(req.nodeId), "", list, 0);
            return { nodes: list };
        }
        case "translate": {
            const r = await session.translateBrowsePath(makeBrowsePath(req.start || "RootFolder", req.path));
            return { status: r.statusCode.name, nodeId: r.targets && r.targets.length ? r.targets[0].targetId.toString() : null };
        }
        case "read": {
            const dvs = await session.read(req.nodeIds.map((n) => ({ nodeId: n, attributeId: AttributeIds.Value })));
            return { values: dvs.map(dataValue) };
        }
        case "readEnum": {
            const dv = await session.read({ nodeId: req.nodeId, attributeId: AttributeIds.DataTypeDefinition });
            const def = dv.value.value;
            const int64 = (v) => (Array.isArray(v) ? v[0] * 4294967296 + v[1] : Number(v));
            return { fields: def && def.fields ? def.fields.map((f) => ({ name: f.name, value: int64(f.value) })) : null,
                status: dv.statusCode.name };
        }
        case "write": {
            const status = await session.write({
                nodeId: req.nodeId, attributeId: AttributeIds.Value,
                value: { value: { dataType: DataType[req.dataType], value: req.value } },
            });
            return { status: status.name };
        }
        case "subscribe": {
            const sub = await ensureSubscription(req);
            for (const nodeId of req.nodeIds) {
                const item = ClientMonitoredItem.create(sub, { nodeId, attributeId: AttributeIds.Value },
                    { samplingInterval: req.samplingInterval === undefined ? 0 : req.samplingInterval, discardOldest: true, queueSize: 100 },
                    TimestampsToReturn.Both);
                item.on("changed", (dv) => out({ event: "data", nodeId, received: Date.now(), ...dataValue(dv) }));
            }
            return {};
        }
        case "events": {
            const sub = await ensureSubscription(req);
            const filter = constructEventFilter(ALARM_FIELDS);
            const item = ClientMonitoredItem.create(sub,
                { nodeId: req.nodeId || "ns=0;i=2253", attributeId: AttributeIds.EventNotifier },
                { queueSize: 1000, filter, discardOldest: true }, TimestampsToReturn.Neither);
            item.on("changed", (fields) => {
                const e = { event: "alarm", source: req.nodeId || "ns=0;i=2253" };
                ALARM_FIELDS.forEach((name, i) => {
                    const v = fields[i];
                    e[name.replace(/^1:/, "")] = v && v.value !== undefined ? jsonValue(v.value) : null;
                });
                out(e);
            });
            await new Promise((resolve) => setTimeout(resolve, 100));
            if (req.refresh) {
                await session.call({ objectId: "ns=0;i=2782", methodId: "ns=0;i=3875",
                    inputArguments: [{ dataType: DataType.UInt32, value: sub.subscriptionId }] });
            }
            return {};
        }
        case "call": {
            const inputArguments = (req.args || []).map((a) => ({ dataType: DataType[a.type], value: a.value }));
            const r = await session.call({ objectId: req.objectId, methodId: req.methodId, inputArguments });
            return { status: r.statusCode.name, code: r.statusCode.value >>> 0 };
        }
        case "acknowledge": {
            const status = await session.acknowledgeCondition(coerceNodeId(req.conditionId),
                Buffer.from(req.eventId, "base64"), req.comment || "");
            return { status: status.name };
        }
        case "close": {
            if (subscription) { await subscription.terminate().catch(() => {}); subscription = null; }
            if (session) { await session.close().catch(() => {}); session = null; }
            if (client) { await client.disconnect().catch(() => {}); client = null; }
            return {};
        }
        case "nodeset": {
            // the NodeSet2 in node-opcua's own address space, with the standard one
            const { AddressSpace } = require("node-opcua-address-space");
            const { generateAddressSpace } = require("node-opcua-address-space/nodeJS");
            const { nodesets } = require("node-opcua-nodesets");
            const addressSpace = AddressSpace.create();
            const warnings = [];
            const warn = console.warn, log = console.log;
            console.warn = (...a) => warnings.push(a.join(" "));
            console.log = (...a) => warnings.push(a.join(" "));
            try {
                // with the companion specifications it is built on (DI, IA, Machinery)
                const files = [nodesets.standard, ...(req.companions || []).map((name) => nodesets[name]), req.file];
                await generateAddressSpace(addressSpace, files);
            } finally {
                console.warn = warn; console.log = log;
            }
            const ns = addressSpace.getNamespaceIndex(req.uri);
            const sensor = addressSpace.findObjectType("GraspSensorType", ns);
            const alarm = addressSpace.findObjectType("SlipAlarmType", ns);
            const enumeration = addressSpace.findDataType("GraspStateEnumeration", ns);
            // every instance declaration of the sensor type, by browse path: its type
            // definition (namespace URI and browse name) and its modelling rule
            const uris = addressSpace.getNamespaceArray().map((n) => n.namespaceUri);
            const declarations = {};
            const walk = (node, prefix) => {
                for (const child of node.getAggregates ? node.getAggregates() : []) {
                    const p = prefix + (prefix ? "/" : "") + child.browseName.name;
                    if (declarations[p]) continue;
                    let td = null;
                    try { td = child.nodeClass === NodeClass.Method ? null : child.typeDefinitionObj; } catch (err) { td = null; }
                    declarations[p] = {
                        nodeClass: NodeClass[child.nodeClass],
                        type: td ? uris[td.nodeId.namespace] + "#" + td.browseName.name : null,
                        browseNamespace: uris[child.browseName.namespaceIndex],
                        rule: child.modellingRule || null,
                        addIn: (node.findReferencesExAsObject ? node.findReferencesExAsObject("HasAddIn") : [])
                            .some((r) => r === child),
                    };
                    walk(child, p);
                }
            };
            if (sensor) walk(sensor, "");
            const result = {
                namespace: ns,
                declarations,
                sensorComponents: sensor ? sensor.getComponents().map((c) => c.browseName.name) : null,
                sensorMethods: sensor ? sensor.getMethods().map((c) => c.browseName.name) : null,
                alarmIsAlarmCondition: alarm ? alarm.isSubtypeOf(addressSpace.findEventType("AlarmConditionType")) : false,
                alarmProperties: alarm ? alarm.getProperties().map((c) => c.browseName.name) : null,
                enumFields: enumeration ? enumeration.getEnumDefinition().fields.map((f) => f.name) : null,
                enumStrings: enumeration && enumeration.getChildByName("EnumStrings")
                    ? Array.from(enumeration.getChildByName("EnumStrings").readValue().value.value || []).map((t) => t.text) : null,
                warnings,
            };
            addressSpace.dispose();
            return result;
        }
        default:
            throw new Error("unknown op " + req.op);
    }
}

const rl = readline.createInterface({ input: process.stdin });
rl.on("line", async (line) => {
    let req;
    try {
        req = JSON.parse(line);
    } catch (err) {
        out({ ok: false, error: "not JSON: " + line });
        return;
    }
    try {
        const result = await handle(req);
        out({ id: req.id, ok: true, ...result });
    } catch (err) {
        const status = err.statusCode ? err.statusCode.name : (err.response && err.response.responseHeader
            ? err.response.responseHeader.serviceResult.name : null);
        out({ id: req.id, ok: false, error: String(err.message || err).split("\n")[0], status });
    }
});
rl.on("close", async () => {
    try { await handle({ op: "close" }); } catch (err) { /* exiting */ }
    process.exit(0);
});
out({ event: "ready", node: process.version });
