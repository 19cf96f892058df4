:- module(dfrl_round_log,
          [ log_round/6,                % +Log, +Agent, +Method, +Epoch, +End, +State
            log_control/5,              % +Log, +Agent, +Round, +Command, +Status
            log_event/2,                % +Log, +Dict
            check_log/1,                % +Log
            log_path_ok/1,              % +File
            log_text/2                  % +Term, -String
          ]).
:- use_module('../tartarus', [current_node/1]).
:- use_module(log_outbox, [outbox_post/4]).
:- autoload(library(error), [must_be/2]).
:- autoload(library(lists), [memberchk/2]).
:- autoload(library(apply), [maplist/3, foldl/4]).
:- autoload(library(http/json), [json_write_dict/3]).

/** <module> The round log of the dFRL agent (dfrl_agent.pl)

Writing the events of a dFRL agent, one JSON object per line, to the
log its plan names. The agent (dfrl_agent.pl) decides what happens and
when; this module only turns an event into a line and puts the line
where the log says, wherever the agent is.

A log is a file name (the agent appends to it on the host it runs on:
one machine, or a shared disk), or console(Host, Port, File): every line
goes to the console node at Host:Port (platform event dfrl_log/3 of
dfrl_console.pl), which appends it to its File, on the driver's disk.
It goes there through the outbox of the node the agent is on
(log_outbox.pl): the line is appended to the node's kept log on this
host, if the host names one, and queued; a thread of the node posts it,
and tries again until the console answers. The agent never waits for
the console. A file is opened, written and closed per line.

```
{"event":"round","agent":"fed_q","round":3,"start":1764600000.12,
 "end":1764600000.25,"hops":8,"bytes":4860,"method":"average",
 "visited":["r1","r2","r3"],"skipped":[{"robot":"r4","reason":"..."}],
 "retries":2,"epoch":1}                   (and "error":"..." if the method failed;
                                          "itinerary":"tree","fanout":2 for a tree round)
{"event":"control","agent":"fed_q","round":4,"command":"method(median)",
 "status":"applied","time":1764600000.3}  (or "ignored" with a "reason")
{"event":"resurrected","agent":"fed_q","round":5,"epoch":2,
 "from":"host:port","dead":"host:port","time":1764600003.5}
{"event":"superseded","agent":"fed_q","round":5,"epoch":1,"by":2}
{"event":"finished","agent":"fed_q","round":16}
{"event":"aborted","agent":"fed_q","round":1,"error":"..."}
```

`visited` lists the robots whose tables went into the aggregate, in the
order of the forward pass; `skipped` the robots of the itinerary that
could not be read, reached or written, with the error as text (for a
stop that could not be reached, with how long the agent tried: "...
(skipped after 1.50 s; skip_after 4 s)");
`retries` how many moves of the round were tried again; `epoch` the
epoch of the copy that logged it. `error` (only then) says that an
aggregation hook failed or threw that round (which hook, and the error):
the round was aborted there, no robot read after it and no table
written, so every robot keeps its own table; the next round tries again.
`resurrected` is logged by the copy that a stop (`from`) resurrected
after the node `dead` was lost with the agent on it (`time`: when, by
the clock of `from`), `superseded` by a
late original as it retires. `aborted` is logged only by an agent
launched with the event `launch` that can reach no stop.

A line is never dropped silently: a console that cannot be reached
gets it later, from the outbox, and the node's kept log has it anyway;
an outbox that is full, or a line that cannot be written at all, is a
warning (never an error that would stop the agent).
*/

%!  log_round(+Log, +Agent, +Method, +Epoch, +End, +State) is det.
%
%   Log the `round` event of the round that State (the agent's round
%   state dict, see dfrl_round_state.pl) describes, ended at time End
%   by the copy of Agent with epoch Epoch, aggregating with Method. A
%   round whose aggregation failed (State has a key `error`) logs it; a
%   round finished with Method after its own method failed (State has a
%   key `fallback`) logs that one as failed_method, with its error.

log_round(Log, Agent, Method, Epoch, End, S) :-
    get_dict(round, S, Round),
    get_dict(start, S, Start),
    get_dict(hops, S, Hops),
    get_dict(bytes, S, Bytes),
    get_dict(visited, S, Visited0),
    get_dict(skipped, S, Skipped0),
    get_dict(retries, S, Retries),
    maplist(log_text, Visited0, Visited),
    maplist(skip_json, Skipped0, Skipped),
    Event = _{event:round, agent:Agent, round:Round, start:Start,
              end:End, hops:Hops, bytes:Bytes, method:Method,
              visited:Visited, skipped:Skipped, retries:Retries,
              epoch:Epoch},
    (   get_dict(itinerary, S, tree(K))
    ->  Event1 = Event.put(_{itinerary:tree, fanout:K})
    ;   Event1 = Event
    ),
    (   get_dict(error, S, Error)
    ->  log_event(Log, Event1.put(error, Error))
    ;   get_dict(fallback, S, failed(Failed, Error))
    ->  log_event(Log, Event1.put(_{error:Error, failed_method:Failed}))
    ;   log_event(Log, Event1)
    ).

skip_json(skip(Robot, Reason), _{robot:R, reason:Reason}) :-
    log_text(Robot, R).

%!  log_control(+Log, +Agent, +Round, +Command, +Status) is det.
%
%   Log the `control` event of Command, taken by Agent at the start of
%   Round. Status is `applied` or ignored(Reason) (Reason a string).

log_control(Log, Agent, Round, Command, Status) :-
    format(string(C), '~q', [Command]),
    get_time(Time),
    (   Status = ignored(Why)
    ->  log_event(Log, _{event:control, agent:Agent, round:Round, command:C,
                         status:ignored, reason:Why, time:Time})
    ;   log_event(Log, _{event:control, agent:Agent, round:Round, command:C,
                         status:applied, time:Time})
    ).

%!  log_text(+Term, -String) is det.
%
%   String is Term written with `~w`. Names become JSON strings this way
%   (an atom `true` or `null` would otherwise be written as a JSON
%   constant).

log_text(X, S) :-
    format(string(S), '~w', [X]).

%!  check_log(+Log) is det.
%
%   Check that Log names a round log: a file name (atomic), or
%   console(Host, Port, File) (see the module comment). Whether a file
%   may be written is decided where a line is written (log_path_ok/1).
%
%   @error type_error(atomic, Log), or of Host, Port (integer) or File.

check_log(console(H, P, F)) :-
    !,
    must_be(atomic, H), must_be(integer, P), must_be(atomic, F).
check_log(Log) :-
    must_be(atomic, Log).

%!  log_event(+Log, +Dict) is det.
%
%   Write Dict as one JSON line to Log (see check_log/1). The agent name
%   and method, atoms, are written as strings. A line for a console goes
%   to the outbox of the current node (log_outbox.pl) and this returns
%   at once: the console may be unreachable for a while.

log_event(Log, Dict0) :-
    foldl(stringify, [agent, method], Dict0, Dict),
    with_output_to(string(Line), json_write_dict(current_output, Dict, [width(0)])),
    (   Log = console(H, P, File)
    ->  catch(( current_node(Node),
                outbox_post(Node, H:P, File, Line)
              ),
              E,
              print_message(warning, format("dfrl: round log line for console ~w:~w \c
                                             not queued: ~p", [H, P, E])))
    ;   append_line_or_warn(Log, Line)
    ).

append_line_or_warn(File, Line) :-
    catch(append_line(File, Line), E,
          print_message(warning, format("dfrl: round log line not written: ~p", [E]))).

%   The log path comes with the agent, from whichever node sent it: it
%   may only name a round log (`.log` or `.jsonl`) in a directory that
%   exists; the agent never creates directories or writes other files.
append_line(File, Line) :-
    (   log_path_ok(File)
    ->  true
    ;   throw(error(permission_error(append, round_log, File),
                    context(dfrl_round_log:append_line/2,
                            'a round log must be a .log or .jsonl file in an existing directory')))
    ),
    setup_call_cleanup(
        open(File, append, Out, [encoding(utf8)]),
        format(Out, "~s~n", [Line]),
        close(Out)).

%!  log_path_ok(+File) is semidet.
%
%   True if the agent may append to File: a `.log` or `.jsonl` file
%   (not a directory) in a directory that exists.

log_path_ok(File) :-
    atomic(File),
    file_name_extension(_, Ext, File),
    memberchk(Ext, [log, jsonl]),
    file_directory_name(File, Dir),
    exists_directory(Dir),
    \+ exists_directory(File).

stringify(Key, D0, D) :-
    (   get_dict(Key, D0, V)
    ->  log_text(V, S),
        put_dict(Key, D0, S, D)
    ;   D = D0
    ).
