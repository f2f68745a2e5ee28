// Mounts Foxglove Studio 1.48 (the npm package's prebuilt app) as its web
// build does, with the layout at /layout.json stored under the id the URL
// names and the remote-file data source the URL opens. Errors the app
// reports (panel crashes among them) are collected in window.__studioErrors.
(async () => {
  window.__studioErrors = [];
  setReportErrorHandler((e) => window.__studioErrors.push(String((e && e.stack) || e)));
  const layoutId = new URLSearchParams(location.search).get("layoutId");
  const data = await (await fetch("/layout.json")).json();
  const stored = new Map([[layoutId, migrateLayout({ id: layoutId, name: "tortwin", permission: "CREATOR_WRITE", data })]]);
  const namespaces = new Map([["local", stored]]);
  const layoutStorage = {
    async list(ns) { return [...(namespaces.get(ns)?.values() ?? [])]; },
    async get(ns, id) { return namespaces.get(ns)?.get(id); },
    async put(ns, layout) {
      if (!namespaces.has(ns)) namespaces.set(ns, new Map());
      namespaces.get(ns).set(layout.id, layout);
      return layout;
    },
    async delete(ns, id) { namespaces.get(ns)?.delete(id); },
    async importLayouts() {},
  };
  const settings = new Map(Object.entries({
    "ui.open-dialog-startup": false,
    colorScheme: "light",
    "telemetry.telemetryEnabled": false,
    "telemetry.crashReportingEnabled": false,
  }));
  const listeners = new Map();
  const appConfiguration = {
    get: (key) => settings.get(key),
    async set(key, value) {
      settings.set(key, value);
      listeners.get(key)?.forEach((cb) => cb(value));
    },
    addChangeListener(key, cb) {
      if (!listeners.has(key)) listeners.set(key, new Set());
      listeners.get(key).add(cb);
    },
    removeChangeListener(key, cb) { listeners.get(key)?.delete(cb); },
  };
  overwriteFetch();
  await waitForFonts();
  await initI18n();
  ReactDOM.render(
    React.createElement(App, {
      deepLinks: [location.href],
      dataSources: [new RemoteDataSourceFactory()],
      appConfiguration,
      layoutStorage,
      extensionLoaders: [],
      enableGlobalCss: true,
    }),
    document.getElementById("root"),
  );
  window.__studioMounted = true;
})().catch((e) => window.__studioErrors.push("harness: " + ((e && e.stack) || e)));
