"""The plugin object: registers the Processing provider (desktop and qgis_process) and, in the
desktop, offers to install missing Python packages into QGIS's own Python."""
from qgis.core import QgsApplication

from .provider.provider import GroundSieveProvider

LOG_TAG = "GroundSieve"
#: the plugin's submenu of Plugins (iface.addPluginToMenu)
MENU = "&GroundSieve"


class GroundSievePlugin:
    def __init__(self, iface):
        self.iface = iface  # None under qgis_process
        self.provider = None
        self.message = None  # the message bar item about missing packages (or the install's outcome)
        self.task = None     # the running install, if any
        self.installing = False  # an install runs: a second one is not started
        self.install_action = None  # Plugins > GroundSieve > Install Python packages…

    def initProcessing(self):  # noqa: N802 (QGIS API name)
        if self.provider is None:
            provider = GroundSieveProvider()
            # A refused provider (e.g. the id already registered) is deleted by the registry.
            if QgsApplication.processingRegistry().addProvider(provider):
                self.provider = provider

    def initGui(self):  # noqa: N802 (QGIS API name)
        self.initProcessing()
        if self.iface is not None:
            self.add_menu()
            self.check_dependencies()

    def add_menu(self):
        """Plugins > GroundSieve > Install Python packages…: the installer, also once the message
        bar's item is closed (and on a QGIS where nothing is missing, it says so)."""
        from qgis.PyQt.QtWidgets import QAction
        self.install_action = QAction("Install Python packages…", self.iface.mainWindow())
        self.install_action.setToolTip("Install the Python packages GroundSieve needs into QGIS's Python (pip)")
        self.install_action.triggered.connect(lambda _checked=False: self.install_missing())
        self.iface.addPluginToMenu(MENU, self.install_action)

    # -- missing packages ------------------------------------------------------------------------

    def missing(self):
        from .dependencies import TRAINING, missing_dependencies
        return missing_dependencies(TRAINING)

    def check_dependencies(self):
        """Say what is missing where it stays: a message bar item with an Install button (no
        timeout) and the full text, with the exact pip command, in the log."""
        from qgis.core import Qgis, QgsMessageLog

        from .dependencies import MENU_ENTRY, NOT_PIP, command_text, install_command, missing_dependencies
        missing = self.missing()
        if not missing:
            return []
        pip_names = [m for m in missing if m not in NOT_PIP]
        level = Qgis.Warning
        if missing_dependencies():
            text = f"needs the Python packages {', '.join(missing)}."
        else:  # (a warning on every start while 13 of 14 algorithms ran: a QGIS plugin reviewer)
            text = (f"needs {', '.join(missing)} only to train Random Forest models; every other algorithm "
                    "works without it.")
            level = Qgis.Info
        detail = ("The GroundSieve algorithms that need them stop with a message until they are installed "
                  f"into QGIS's Python (the Install… button, or {MENU_ENTRY}).")
        try:
            command = command_text(install_command(pip_names))
        except RuntimeError as err:
            command = str(err)
        QgsMessageLog.logMessage(f"GroundSieve {text} {detail} Install command: {command}", LOG_TAG, level)
        # (information goes away by itself: a code reviewer saw it stay on every start)
        self.show_message(text, level, pip_names, duration=0 if level == Qgis.Warning else 15)
        return missing

    def show_message(self, text, level, packages=None, duration=0):
        """Put ``text`` in the message bar (replacing this plugin's previous item), staying until
        closed (``duration`` 0; else that many seconds), with an Install… button when ``packages`` (pip
        names) are to be installed."""
        from qgis.PyQt.QtWidgets import QPushButton
        bar = self.iface.messageBar()
        self.close_message()
        item = bar.createMessage("GroundSieve", text)
        if packages:
            button = QPushButton("Install…")
            button.clicked.connect(lambda _checked=False: self.ask_and_install(packages))
            item.layout().addWidget(button)
        self.message = bar.pushWidget(item, level, duration)
        return self.message

    def close_message(self):
        if self.message is not None and self.iface is not None:
            try:
                self.iface.messageBar().popWidget(self.message)
            except RuntimeError:  # closed by the user: Qt has deleted it
                pass
        self.message = None

    def install_missing(self, confirm=None):
        """The menu entry: install what is missing (asking first), or say nothing is."""
        from qgis.core import Qgis

        from .dependencies import NOT_PIP
        missing = self.missing()
        packages = [m for m in missing if m not in NOT_PIP]
        if not packages:
            text = (f"{', '.join(missing)} cannot be installed with pip: it comes with QGIS (or the system's GDAL "
                    "bindings, python3-gdal)." if missing else "every Python package it needs is installed.")
            self.iface.messageBar().pushMessage("GroundSieve", text, level=Qgis.Warning if missing else Qgis.Info,
                                                duration=10)
            return None
        return self.ask_and_install(packages, confirm=confirm)

    def ask_and_install(self, packages, confirm=None):
        """Check that QGIS's Python has pip, show the exact command, ask, then run pip in a
        background task; one install at a time (a second click while pip runs is told so)."""
        from qgis.core import Qgis, QgsMessageLog
        from qgis.PyQt.QtWidgets import QMessageBox

        from .dependencies import NO_PIP_HINT, command_text, install_command, pip_available
        if self.installing:
            if self.iface is not None:
                self.iface.messageBar().pushMessage("GroundSieve", "already installing the Python packages: "
                                                    "see the task in the status bar.", level=Qgis.Info, duration=5)
            return None
        try:
            cmd = install_command(packages)
        except RuntimeError as err:
            QgsMessageLog.logMessage(f"GroundSieve: {err}", LOG_TAG, Qgis.Critical)
            if self.iface is not None:
                self.show_message("QGIS's Python was not found: see Log Messages > GroundSieve.", Qgis.Critical)
            return None
        has_pip, said = pip_available(cmd[0])
        if not has_pip:
            QgsMessageLog.logMessage(f"GroundSieve: {cmd[0]} -m pip --version: {said}\n{NO_PIP_HINT}",
                                     LOG_TAG, Qgis.Critical)
            if self.iface is not None:  # short (the bar cuts long text), with the button to try again
                self.show_message("QGIS's Python has no pip. Debian/Ubuntu: sudo apt install python3-pip, "
                                  "then Install… again (more in Log Messages > GroundSieve).", Qgis.Critical, packages)
            return None
        command = command_text(cmd)
        question = (f"GroundSieve will install {', '.join(packages)} into QGIS's Python for this user "
                    f"with pip, keeping numpy and scipy at the versions QGIS runs with:\n\n{command}\n\n"
                    "This downloads the packages from the Python Package Index. Go ahead?")
        if confirm is None:
            window = self.iface.mainWindow() if self.iface is not None else None
            answer = QMessageBox.question(window, "GroundSieve: install Python packages", question)
            confirm = answer == QMessageBox.Yes
        if not confirm or self.installing:  # (a click that came while the question was open)
            return None
        self.installing = True
        if self.install_action is not None:
            self.install_action.setEnabled(False)
        self.task = InstallTask(packages, self.installed)
        QgsApplication.taskManager().addTask(self.task)
        return self.task

    def installed(self, ok, output):
        """After pip: say what happened, shortly in the bar and fully in the log; clear the warning
        when done, else leave an Install… button to try again."""
        from qgis.core import Qgis, QgsMessageLog
        self.installing = False
        if self.install_action is not None:
            self.install_action.setEnabled(True)
        still = self.missing()
        QgsMessageLog.logMessage((output[-4000:] or "(pip printed nothing)")
                                 + (f"\nStill missing: {', '.join(still)}" if still else ""),
                                 LOG_TAG, Qgis.Info if ok else Qgis.Critical)
        if self.iface is None:
            return still
        if ok and not still:
            self.close_message()
            self.iface.messageBar().pushMessage("GroundSieve", "Python packages installed; the algorithms are ready.",
                                                level=Qgis.Success, duration=10)
        else:
            from .dependencies import NOT_PIP
            self.show_message("installing the Python packages failed: see Log Messages > GroundSieve.",
                              Qgis.Critical, [m for m in still if m not in NOT_PIP])
        return still

    def unload(self):
        if self.provider is not None:
            QgsApplication.processingRegistry().removeProvider(self.provider)
            self.provider = None
        if self.install_action is not None and self.iface is not None:
            self.iface.removePluginMenu(MENU, self.install_action)
            self.install_action = None
        self.close_message()


class InstallTask:
    """pip in a QgsTask (off the GUI thread); ``done(ok, output)`` is called on the GUI thread."""

    def __new__(cls, packages, done):
        from qgis.core import QgsTask

        from .dependencies import install

        class _Task(QgsTask):
            def __init__(self):
                super().__init__("GroundSieve: installing Python packages", QgsTask.CanCancel)
                self.ok, self.output = False, ""

            def run(self):
                try:
                    self.ok, self.output = install(packages, log=lambda _msg: None)
                except Exception as err:  # noqa: BLE001 - said in the log by done(), not lost in the task
                    self.ok, self.output = False, f"{type(err).__name__}: {err}"
                return self.ok

            def finished(self, _result):
                done(self.ok, self.output)

        return _Task()
