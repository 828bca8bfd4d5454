// Mounts Foxglove Studio's App (from the @foxglove/studio-base web bundle) the way its web
// shell did, with the app settings and layouts kept in memory: the layout served beside this
// page is the only one, so the session starts from it.
/* global React, ReactDOM */
(async () => {
  const studio = window; // the bundle's exports are globals
  const report = (msg) => {
    window.__screenshotError = String(msg);
    console.error("screenshot page:", msg);
  };
  try {
    const layoutResponse = await fetch("/layout.json");
    if (!layoutResponse.ok) {
      throw new Error(`GET /layout.json: ${layoutResponse.status}`);
    }
    const layoutData = await layoutResponse.json();
    const LAYOUT_ID = "microrobot";
    const now = new Date().toISOString();

    const layouts = new Map();
    layouts.set(LAYOUT_ID, {
      id: LAYOUT_ID,
      name: "microrobot recording",
      permission: "CREATOR_WRITE",
      baseline: { data: layoutData, savedAt: now },
      working: undefined,
      syncInfo: undefined,
    });
    const layoutStorage = {
      list: async () => [...layouts.values()],
      get: async (_ns, id) => layouts.get(id),
      put: async (_ns, layout) => {
        layouts.set(layout.id, layout);
        return layout;
      },
      delete: async (_ns, id) => {
        layouts.delete(id);
      },
      importLayouts: async () => {},
    };

    const settings = new Map([
      ["colorScheme", "light"],
      ["timezone", "UTC"],
      ["ui.open-dialog-startup", false],
      ["hideSignInPrompt", true],
      ["updates.enabled", false],
      ["telemetry.telemetryEnabled", false],
      ["telemetry.crashReportingEnabled", false],
    ]);
    const listeners = new Map();
    const appConfiguration = {
      get: (key) => settings.get(key),
      set: async (key, value) => {
        settings.set(key, value);
        for (const cb of listeners.get(key) ?? []) {
          cb(value);
        }
      },
      addChangeListener: (key, cb) => {
        listeners.set(key, [...(listeners.get(key) ?? []), cb]);
      },
      removeChangeListener: (key, cb) => {
        listeners.set(key, (listeners.get(key) ?? []).filter((c) => c !== cb));
      },
    };

    // The 3D panel's first-use hint ("Open settings to configure topics and layers") would
    // cover the scene: mark it as already shown in the user profile the app keeps.
    localStorage.setItem(
      "studio.profile-data",
      JSON.stringify({ onboarding: { settingsTooltipShownForPanelTypes: ["3D"] } }),
    );

    await studio.initI18n();
    ReactDOM.render(
      React.createElement(studio.App, {
        deepLinks: [window.location.href],
        appConfiguration,
        dataSources: [new studio.RemoteDataSourceFactory()],
        layoutStorage,
        extensionLoaders: [],
        enableGlobalCss: true,
      }),
      document.getElementById("root"),
    );
    window.__screenshotMounted = true;
  } catch (err) {
    report(err && err.stack ? err.stack : err);
  }
})();
