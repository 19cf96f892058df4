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
:- autoload(library(lists), [member/2, append/3]).

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
    in the queue is dropped (it stays in the kept log), with a warning
    once per node and the count in outbox_property/2.
  - One delivery thread per node takes the lines in order and posts
    them to their console (platform event dfrl_log/3 of dfrl_console.pl),
    every line waiting (at most 500, any agent's) in one post, which the
    console appends in one go: it runs each post in a thread of its own,
    so lines posted apart in quick succession (a backlog) could be
    appended out of order. A post that fails is tried again, with the
    lines queued meanwhile added, after 0.2 s, doubling to at most 5 s,
    until it is accepted or the node stops. An outage is a warning when
    it starts and a message when the lines flow again. The lines being
    posted (at most 500, and at most `max_lines`) are held by the
    thread, beside the queue: the outbox holds at most twice `max_lines`.

A line may reach the console twice (its post was accepted but the reply
was lost, and it was sent again): lines are whole JSON events with the
agent's times in them, so the readers of rounds_<agent>.log
(experiments/driver/results/agent_log.py) drop a line identical to one
already read. Without outbox_configure/2 a node keeps the lines only in
its outbox (memory): lines dropped when it is full are lost, and said so.

The outbox costs the agent a file append and a queue send once per
logged event (a round, a control, an ending), never per hop.

Threading: outbox_post/4 is called by agent threads; the delivery
thread of a node is started by its first post and ended when its node
stops (hook node:node_stopping/1; its queue is destroyed then; lines not
delivered are in the kept log). The facts below are changed under the
mutex log_outbox.
*/

:- dynamic
    conf/3,                     % Node, KeepDir (or none), MaxLines
    outbox/3,                   % Node, Queue, Thread
    tally/3,                    % Node, Key, Count: posted, delivered, dropped,
                                % failures; outage (failed posts since the last
                                % delivery, while the console does not answer)
    said_full/1.                % Node: the warning on a full outbox was given

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
    count(Node, posted),
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
        thread_create(deliver_loop(Node, Queue), Tid, []),
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
    ;   with_mutex(log_outbox, assertz(said_full(Node))),
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
    count(Node, Key, 1).

count(Node, Key, K) :-
    with_mutex(log_outbox,
               (   (   retract(tally(Node, Key, N0)) -> N is N0 + K ; N = K ),
                   assertz(tally(Node, Key, N))
               )).

		 /*******************************
		 *           DELIVERY		*
		 *******************************/

deliver_loop(Node, Queue) :-
    call_cleanup(catch(deliver_lines(Node, Queue), E, stopped(Node, E)),
                 forget_outbox(Node, Queue)).

deliver_lines(Node, Queue) :-
    node_set_current(Node),
    deliver_from(Node, Queue, []).

%   Pending: lines taken from the queue, not delivered yet, in order.
deliver_from(Node, Queue, Pending) :-
    (   Pending == [],
        \+ thread_peek_message(Queue, _)
    ->  (   thread_get_message(Queue, Msg, [timeout(1)])
        ->  deliver_from(Node, Queue, [Msg])
        ;   node_runs(Node)
        ->  deliver_from(Node, Queue, [])
        ;   true
        )
    ;   attempt(Node, Queue, Pending, 0.2)
    ).

%   Post the lines waiting for the first console, topped up from the
%   queue (at most batch_lines/2), as one post; on failure wait, top up
%   and try again, until the console accepts them or the node stops. The
%   console runs each post in a thread of its own: lines posted apart in
%   quick succession could be appended out of order; a batch is appended
%   in one go, and a backlog goes as one batch (up to batch_lines/2).
attempt(Node, Queue, Pending0, Wait) :-
    batch_lines(Node, Max),
    top_up(Queue, Pending0, Max, Pending),
    Pending = [line(Console, _, _)|_],
    lead(Pending, Console, Entries, Rest),
    length(Entries, N),
    (   node_property(Node, link(Link))
    ->  catch(agent_post(Console, platform, dfrl_log, Link, [entries(Entries)],
                         [connect_timeout(5), reply_timeout(10)]),
              E, true)
    ;   E = node_stopped
    ),
    (   var(E)
    ->  count(Node, delivered, N),
        outage_over(Node, Console),
        deliver_from(Node, Queue, Rest)
    ;   E \== node_stopped,
        node_runs(Node)
    ->  outage(Node, Console, E),
        sleep(Wait),
        Wait1 is min(5.0, Wait * 2),
        attempt(Node, Queue, Pending, Wait1)
    ;   true                            % the node stopped
    ).

%   At most 500 lines, and no more than the queue holds: the outbox holds
%   at most twice max_lines.
batch_lines(Node, Max) :-
    outbox_property(Node, max_lines(M)),
    Max is min(500, M).

top_up(Queue, Pending0, Max, Pending) :-
    length(Pending0, N),
    Room is Max - N,
    take_more(Queue, Room, More),
    append(Pending0, More, Pending).

take_more(Queue, Room, More) :-
    (   Room > 0,
        thread_get_message(Queue, Msg, [timeout(0)])
    ->  More = [Msg|Rest],
        Room1 is Room - 1,
        take_more(Queue, Room1, Rest)
    ;   More = []
    ).

%   The leading lines for Console, as File-Line pairs, and the rest.
lead([line(C, F, L)|Msgs], C, [F-L|Entries], Rest) :-
    !,
    lead(Msgs, C, Entries, Rest).
lead(Msgs, _, [], Msgs).

outage(Node, Console, E) :-
    (   tally(Node, outage, _)
    ->  true
    ;   print_message(warning,
                      format("dfrl: round log to console ~w failed (~p); \c
                              the lines wait in the outbox of ~w and are sent \c
                              when it answers", [Console, E, Node]))
    ),
    count(Node, outage),
    count(Node, failures).

outage_over(Node, Console) :-
    (   retract(tally(Node, outage, Failures))
    ->  print_message(informational,
                      format("dfrl: round log: console ~w reached again after \c
                              ~D failed posts; the lines kept meanwhile are sent",
                             [Console, Failures]))
    ;   true
    ).

stopped(_, E) :-
    (   (   E == outbox_stop
        ;   E = error(existence_error(platform, _), _)
        )
    ->  true
    ;   print_message(warning, E)
    ).

:- multifile node:node_stopping/1.

%   The node stops: its delivery thread ends now (it may be waiting for a
%   reply or sleeping before a retry); waited for at most 2 s, then left
%   to end by itself.
node:node_stopping(Node) :-
    (   outbox(Node, _, Tid)
    ->  catch(thread_signal(Tid, throw(outbox_stop)), _, true),
        (   wait_thread_end(Tid, 100)
        ->  catch(thread_join(Tid, _), _, true)
        ;   catch(thread_detach(Tid), _, true)
        )
    ;   true
    ).

wait_thread_end(Tid, N) :-
    (   \+ catch(thread_property(Tid, status(running)), _, fail)
    ->  true
    ;   N > 0
    ->  sleep(0.02),
        N1 is N - 1,
        wait_thread_end(Tid, N1)
    ).

forget_outbox(Node, Queue) :-
    with_mutex(log_outbox,
               (   retractall(outbox(Node, Queue, _)),
                   retractall(said_full(Node))
               )),
    catch(message_queue_destroy(Queue), _, true).

node_runs(Node) :-
    node_property(Node, id(_)).

		 /*******************************
		 *            STATE		*
		 *******************************/

%!  outbox_property(+Node, ?Property) is nondet.
%
%   Properties of the outbox of Node: posted(N) (lines handed to it),
%   queued(N) (lines waiting, not counting one being posted),
%   delivered(N), dropped(N) (from a full outbox, or not sent when the
%   node stopped), failures(N) (posts that failed), keep_dir(Dir) (or
%   none), max_lines(N).

outbox_property(Node, Property) :-
    must_be(atom, Node),
    (   nonvar(Property)
    ->  property(Property, Node)
    ;   member(Property, [posted(_), queued(_), delivered(_), dropped(_), failures(_),
                          keep_dir(_), max_lines(_)]),
        property(Property, Node)
    ).

property(queued(N), Node) :-
    (   outbox(Node, Q, _), catch(message_queue_property(Q, size(N)), _, fail)
    ->  true
    ;   N = 0
    ).
property(posted(N), Node) :- tally_of(Node, posted, N).
property(delivered(N), Node) :- tally_of(Node, delivered, N).
property(dropped(N), Node) :- tally_of(Node, dropped, N).
property(failures(N), Node) :- tally_of(Node, failures, N).
property(keep_dir(D), Node) :- ( conf(Node, D0, _) -> D = D0 ; D = none ).
property(max_lines(M), Node) :- ( conf(Node, _, M0) -> M = M0 ; M = 10000 ).

tally_of(Node, Key, N) :-
    (   tally(Node, Key, N0) -> N = N0 ; N = 0 ).

%!  outbox_wait_empty(+Node, +Timeout) is semidet.
%
%   Wait at most Timeout seconds until every line posted to the outbox
%   of Node was delivered or dropped (for a host that ends, and for
%   tests).

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
    tally_of(Node, posted, Posted),
    tally_of(Node, delivered, Delivered),
    tally_of(Node, dropped, Dropped),
    Posted =:= Delivered + Dropped.
