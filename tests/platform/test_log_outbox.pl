/*  plunit tests of the round log's outbox (log_outbox.pl) on in-process
    nodes: a "console" node whose platform event dfrl_log/3 (this file's)
    records the lines it gets, a console that is not listening yet, and a
    full outbox. The real-process test with a frozen console is
    test_log_outbox.py.
*/
:- use_module('../../platform_pl/tartarus').
:- use_module('../../platform_pl/dfrl_agent/log_outbox').
:- use_module(library(plunit)).
:- use_module(library(readutil), [read_file_to_string/3]).

:- dynamic user:got/2.             % File, Line: what the console got, in order
:- dynamic quiet/0.

% the outage and the full outbox are warnings on purpose: counted, not shown
:- multifile user:message_hook/3.
:- dynamic user:message_hook/3.
:- asserta((user:message_hook(_, warning, _) :- quiet)).
:- asserta((user:message_hook(_, informational, _) :- quiet)).

:- initialization(platform_event(user:dfrl_log/3)).

dfrl_log(platform, _Link, entries(Entries)) :-
    forall(member(File-Line, Entries), assertz(got(File, Line))).

wait_for(G) :- wait_for(G, 500).
wait_for(G, N) :- ( call(G) -> true ; N > 0 -> sleep(0.02), N1 is N-1, wait_for(G, N1) ; fail ).

lines(Prefix, N, Lines) :-
    numlist(1, N, Is),
    maplist([I, L]>>format(string(L), "~w ~d", [Prefix, I]), Is, Lines).

kept_lines(File, Lines) :-
    read_file_to_string(File, Text, []),
    split_string(Text, "\n", "", Lines0),
    exclude(==(""), Lines0, Lines).

free_port(Port) :-
    node_start(localhost:0, N, [token(7), default(false)]),
    node_property(N, address(_:Port)),
    node_stop(N).

tmp_dir(Dir) :-
    tmp_file(kept, Dir),
    make_directory(Dir).

cleanup(Nodes) :-
    retractall(user:quiet),
    retractall(got(_, _)),
    forall(member(N, Nodes), catch(node_stop(N), _, true)).

:- begin_tests(log_outbox).

test(kept_and_delivered_after_the_console_comes_up,
     [setup(assertz(user:quiet)), cleanup(cleanup([R, C]))]) :-
    % Prepare: a robot node keeping its lines; its console's port not listening yet
    tmp_dir(Dir),
    free_port(P),
    node_start(localhost:0, R, [token(7), default(false), connect_timeout(1)]),
    outbox_configure(R, [keep_dir(Dir)]),
    lines(round, 5, Lines),
    % Execute: post five lines; then start the console on that port
    get_time(T0),
    forall(member(L, Lines), outbox_post(R, localhost:P, '/driver/rounds_fx.log', L)),
    get_time(T1),
    directory_file_path(Dir, 'rounds_fx.log', Kept),
    kept_lines(Kept, KeptLines),
    assertion(wait_for(( outbox_property(R, failures(F0)), F0 >= 1 ))),
    assertion(\+ got(_, _)),
    node_start(localhost:P, C, [token(7), default(false)]),
    assertion(wait_for(outbox_wait_empty(R, 0.1))),
    % Assert: posting never waited for the console; the kept log had every line at once;
    % the console got them all, in order, once; the failures were counted
    assertion(T1 - T0 < 0.5),
    assertion(KeptLines == Lines),
    findall(F-L, got(F, L), Got),
    findall('/driver/rounds_fx.log'-L, member(L, Lines), Want),
    assertion(Got == Want),
    assertion(outbox_property(R, delivered(5))).

test(full_outbox_drops_the_oldest_keeps_the_file,
     [setup(assertz(user:quiet)), cleanup(cleanup([R, C]))]) :-
    % Prepare: an outbox of 3 lines; no console
    tmp_dir(Dir),
    free_port(P),
    node_start(localhost:0, R, [token(7), default(false), connect_timeout(1)]),
    outbox_configure(R, [keep_dir(Dir), max_lines(3)]),
    lines(line, 10, Lines),
    % Execute: ten lines, then the console comes up
    forall(member(L, Lines), outbox_post(R, localhost:P, 'rounds_fx.log', L)),
    outbox_property(R, dropped(Dropped)),
    node_start(localhost:P, C, [token(7), default(false)]),
    assertion(wait_for(outbox_wait_empty(R, 0.1))),
    % Assert: the kept log has all ten; the outbox held at most 3 queued and 3 being
    % posted: the console got the newest three and some of the oldest, each once, in
    % no guaranteed order (the console runs each post in a thread of its own, see
    % log_outbox.pl: posts in quick succession may be appended in any order; measured:
    % "line 10" before "line 7"); the rest counted as dropped
    directory_file_path(Dir, 'rounds_fx.log', Kept),
    kept_lines(Kept, KeptLines),
    assertion(KeptLines == Lines),
    findall(L, got(_, L), Got),
    length(Got, NGot),
    assertion(NGot + Dropped =:= 10),
    assertion(Dropped >= 4),
    Newest = ["line 8", "line 9", "line 10"],
    assertion(subtract(Newest, Got, [])),
    assertion(subtract(Got, Lines, [])),
    sort(Got, Distinct),
    assertion(length(Distinct, NGot)).

test(no_keep_dir_memory_only, [cleanup(cleanup([R, C]))]) :-
    node_start(localhost:0, C, [token(7), default(false)]),
    node_property(C, address(_:P)),
    node_start(localhost:0, R, [token(7), default(false)]),
    outbox_post(R, localhost:P, 'rounds_fx.log', "one"),
    assertion(wait_for(outbox_wait_empty(R, 0.1))),
    assertion(got('rounds_fx.log', "one")),
    outbox_property(R, keep_dir(none)).

test(bad_options, [error(type_error(positive_integer, 0))]) :-
    outbox_configure(n, [max_lines(0)]).

:- end_tests(log_outbox).
