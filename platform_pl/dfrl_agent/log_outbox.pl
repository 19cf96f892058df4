:- module(log_outbox,
          [ outbox_configure/2,         % +Node, +Options
            outbox_post/4,              % +Node, +Console, +File, +Line
            outbox_property/2,          % +Node, ?Property
            outbox_wait_empty/2         % +Node, +Timeout
          ]).
:- use_module('../node', [node_property/2, node_set_current/1]).
:- use_module('../messages', [agent_post/6]).
:- autoload(library(error), [must_be/2]).
:- autoload(library(option), [option/2, option/3]).
:- autoload(library(lists), [member/2]).

/** <module> The round log's outbox: lines for the console, kept and sent later

The round log (dfrl_round_log.pl) of an agent launched from a console
node posts its lines to that console, which appends them to the run's
rounds_<agent>.log on the driver's disk. The console is not on the
agent's critical path: the agent hands each line to the outbox of the
node it is on and walks on. Per node:

  - The line is first appended to the node's *kept log*,
    `Dir/<base name of File>` (e.g. `Dir/rounds_fed_q.log`), when the
    process that hosts the node named a directory Dir with
    outbox_configure/2 (a robot process names
    `<its results folder>/agent_logs/<robot>`). The kept log holds every
    line the agent logged on that node, delivered or not.
  - The line is put in the node's outbox, a message queue of at most
    `max_lines` lines (default 10000). When it is full the oldest line
    is dropped from the queue (it stays in the kept log), with a
    warning once per node and the count in outbox_property/2.
  - One delivery thread per node takes the lines in order and posts
    each to its console (platform event dfrl_log/3 of dfrl_console.pl);
    a post that fails is tried again, the same line, after 0.2 s,
    doubling to at most 5 s, until it is accepted or the node stops.
    An outage is a warning when it starts and a message when the lines
    flow again.

A line may reach the console twice (its post was accepted but the reply
was lost, and it was sent again): lines are whole JSON events with the
agent's times in them, so the readers of rounds_<agent>.log
(experiments/driver/results/agent_log.py) drop a line identical to one
already read. Without outbox_configure/2 a node keeps the lines only in
its outbox (memory): lines dropped when it is full are lost, and said so.

The outbox costs the agent a file append and a queue send once per
logged event (a round, a control, an ending), never per hop.

Threading: outbox_post/4 is called by agent threads; the delivery
thread of a node is started by its first post and ends a second after
its node stopped (its queue is destroyed then; lines not delivered are
in the kept log). The facts below are changed under the mutex
log_outbox.
*/

:- dynamic
    conf/3,                     % Node, KeepDir (or none), MaxLines
    outbox/3,                   % Node, Queue, Thread
    tally/3,                    % Node, Key (delivered, dropped, failures), Count
    said_full/1,                % Node: the warning on a full outbox was given
    in_flight/1.                % Node: its delivery thread is posting a line

%!  outbox_configure(+Node, +Options) is det.
%
%   Set how the outbox of Node keeps lines. Options:
%
%     - keep_dir(+Dir)      append every line also to `Dir/<base name of
%                           the console's File>` (Dir is made if it does
%                           not exist); `none`: keep lines in memory only
%                           (the default)
%     - max_lines(+N)       lines the outbox holds before it drops the
%                           oldest (default 10000; a line is about 300
%                           bytes)
%
%   Takes effect for lines posted from now on; max_lines for an outbox
%   not yet started (a node's first post starts it).
%
%   @error type_error(atomic, Dir), type_error(positive_integer, N)

outbox_configure(Node, Options) :-
    must_be(atom, Node),
    must_be(list, Options),
    with_mutex(log_outbox,
               (   conf(Node, Dir0, Max0) -> true ; Dir0 = none, Max0 = 10000 )),
    option(keep_dir(Dir), Options, Dir0),
    option(max_lines(Max), Options, Max0),
    must_be(atomic, Dir),
    must_be(positive_integer, Max),
    (   Dir == none
    ->  true
    ;   make_directory_path(Dir)
    ),
    with_mutex(log_outbox,
               (   retractall(conf(Node, _, _)),
                   assertz(conf(Node, Dir, Max))
               )).

%!  outbox_post(+Node, +Console, +File, +Line) is det.
%
%   Keep Line (a string without a newline) in the kept log of Node, if
%   it has one, and queue it for the console at Console (Host:Port),
%   which appends it to its File. Never waits for the console. A line
%   that cannot be kept is a warning.

outbox_post(Node, Console, File, Line) :-
    (   conf(Node, Dir, _), Dir \== none
    ->  file_base_name(File, Base),
        directory_file_path(Dir, Base, Kept),
        catch(append_kept(Kept, Line), E,
              print_message(warning, format("dfrl: round log line not kept in ~w: ~p",
                                            [Kept, E])))
    ;   true
    ),
    node_outbox(Node, Queue),
    enqueue(Node, Queue, line(Console, File, Line), 3).

append_kept(Kept, Line) :-
    setup_call_cleanup(
        open(Kept, append, Out, [encoding(utf8)]),
        format(Out, "~s~n", [Line]),
        close(Out)).

node_outbox(Node, Queue) :-
    (   outbox(Node, Queue0, _)
    ->  Queue = Queue0
    ;   with_mutex(log_outbox, start_outbox(Node, Queue))
    ).

start_outbox(Node, Queue) :-
    (   outbox(Node, Queue0, _)
    ->  Queue = Queue0
    ;   (   conf(Node, _, Max) -> true ; Max = 10000 ),
        message_queue_create(Queue, [max_size(Max)]),
        thread_create(deliver_loop(Node, Queue), Tid, [detached(true)]),
        assertz(outbox(Node, Queue, Tid))
    ).

%   A full queue: drop its oldest line and try again (the delivery
%   thread may have taken one meanwhile); after Tries, the line itself.
enqueue(Node, Queue, Msg, Tries) :-
    (   catch(thread_send_message(Queue, Msg, [timeout(0)]), _, fail)
    ->  true
    ;   Tries > 0
    ->  (   catch(thread_get_message(Queue, _, [timeout(0)]), _, fail)
        ->  dropped(Node)
        ;   true
        ),
        Tries1 is Tries - 1,
        enqueue(Node, Queue, Msg, Tries1)
    ;   dropped(Node)
    ).

dropped(Node) :-
    count(Node, dropped),
    (   said_full(Node)
    ->  true
    ;   assertz(said_full(Node)),
        outbox_property(Node, keep_dir(Where)),
        outbox_property(Node, max_lines(Max)),
        (   Where == none
        ->  print_message(warning, format("dfrl: the round-log outbox of ~w is full (~D \c
                                           lines): its oldest lines are dropped and lost \c
                                           (no kept log on this node)", [Node, Max]))
        ;   print_message(warning, format("dfrl: the round-log outbox of ~w is full (~D \c
                                           lines): its oldest lines are dropped from it; \c
                                           they stay in ~w", [Node, Max, Where]))
        )
    ).

count(Node, Key) :-
    with_mutex(log_outbox,
               (   (   retract(tally(Node, Key, N0)) -> N is N0 + 1 ; N = 1 ),
                   assertz(tally(Node, Key, N))
               )).

		 /*******************************
		 *           DELIVERY		*
		 *******************************/

deliver_loop(Node, Queue) :-
    setup_call_cleanup(
        true,
        catch(deliver_lines(Node, Queue), E, stopped(Node, E)),
        forget_outbox(Node, Queue)).

deliver_lines(Node, Queue) :-
    node_set_current(Node),
    repeat,
    (   thread_get_message(Queue, Msg, [timeout(1)])
    ->  assertz(in_flight(Node)),
        call_cleanup(deliver(Node, Msg, 0.2), retractall(in_flight(Node)))
    ;   true
    ),
    \+ node_runs(Node),
    !.

stopped(_, E) :-
    (   E = error(existence_error(platform, _), _)
    ->  true
    ;   print_message(warning, E)
    ).

forget_outbox(Node, Queue) :-
    with_mutex(log_outbox,
               (   retractall(outbox(Node, Queue, _)),
                   retractall(said_full(Node))
               )),
    catch(message_queue_destroy(Queue), _, true).

node_runs(Node) :-
    node_property(Node, id(_)).

%   Post one line until the console accepts it or the node stops.
deliver(Node, Msg, Wait) :-
    Msg = line(Console, File, Line),
    (   node_property(Node, link(Link))
    ->  deliver(Node, Link, Console, File, Line, Msg, Wait)
    ;   true                            % the node stopped
    ).

deliver(Node, Link, Console, File, Line, Msg, Wait) :-
    catch(agent_post(Console, platform, dfrl_log, Link, [entry(File, Line)],
                     [connect_timeout(5), reply_timeout(10)]),
          E, true),
    (   var(E)
    ->  count(Node, delivered),
        (   retract(tally(Node, outage, Failures))
        ->  print_message(informational,
                          format("dfrl: round log: console ~w reached again after \c
                                  ~D failed posts; delivering the kept lines",
                                 [Console, Failures]))
        ;   true
        )
    ;   node_runs(Node)
    ->  (   tally(Node, outage, _)
        ->  true
        ;   print_message(warning,
                          format("dfrl: round log to console ~w failed (~p); \c
                                  the lines wait in the outbox of ~w and are sent \c
                                  when it answers", [Console, E, Node]))
        ),
        count(Node, outage),
        count(Node, failures),
        sleep(Wait),
        Wait1 is min(5.0, Wait * 2),
        deliver(Node, Msg, Wait1)
    ;   true
    ).

		 /*******************************
		 *            STATE		*
		 *******************************/

%!  outbox_property(+Node, ?Property) is nondet.
%
%   Properties of the outbox of Node: queued(N) (lines waiting, not
%   counting one being posted), delivered(N), dropped(N) (from a full
%   outbox), failures(N) (posts that failed), keep_dir(Dir) (or none),
%   max_lines(N).

outbox_property(Node, Property) :-
    must_be(atom, Node),
    member(Property, [queued(_), delivered(_), dropped(_), failures(_),
                      keep_dir(_), max_lines(_)]),
    property(Property, Node).

property(queued(N), Node) :-
    (   outbox(Node, Q, _), catch(message_queue_property(Q, size(N)), _, fail)
    ->  true
    ;   N = 0
    ).
property(delivered(N), Node) :- tally_of(Node, delivered, N).
property(dropped(N), Node) :- tally_of(Node, dropped, N).
property(failures(N), Node) :- tally_of(Node, failures, N).
property(keep_dir(D), Node) :- ( conf(Node, D0, _) -> D = D0 ; D = none ).
property(max_lines(M), Node) :- ( conf(Node, _, M0) -> M = M0 ; M = 10000 ).

tally_of(Node, Key, N) :-
    (   tally(Node, Key, N0) -> N = N0 ; N = 0 ).

%!  outbox_wait_empty(+Node, +Timeout) is semidet.
%
%   Wait at most Timeout seconds until the outbox of Node holds no line
%   and none is being posted (for a host that ends, and for tests).

outbox_wait_empty(Node, Timeout) :-
    must_be(atom, Node),
    get_time(T0),
    Deadline is T0 + Timeout,
    wait_empty(Node, Deadline).

wait_empty(Node, Deadline) :-
    (   empty(Node)
    ->  true
    ;   get_time(Now),
        Now < Deadline,
        sleep(0.05),
        wait_empty(Node, Deadline)
    ).

empty(Node) :-
    outbox_property(Node, queued(0)),
    \+ in_flight(Node).
