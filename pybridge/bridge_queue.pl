:- module(bridge_queue,
          [ bridge_call/5,              % +Robot, +Op, +PI, +Options, -Reply
            bridge_service_call/3,      % +Op, -Reply, +Options
            bridge_next_request/2,      % -Request, +TimeoutSeconds
            bridge_next_service_request/2, % -Request, +TimeoutSeconds
            bridge_reply/2,             % +Id, +Reply
            bridge_attach_server/0,
            bridge_detach_server/0,
            queue_shutdown/0,
            bridge_stop_threads/2,      % +Timeout, -Remaining
            bridge_stop_threads/3,      % +Timeout, -Remaining, -Aborted
            ensure_request_queue/0,     % (the robot_bridge_requests and service queues)
            check_timeout/1             % +Seconds
          ]).
:- autoload(library(error), [must_be/2, domain_error/2]).
:- autoload(library(option), [option/3]).
:- autoload(library(lists), [member/2]).
:- autoload(library(apply), [include/3]).
:- autoload(library(debug), [debug/3]).

/** <module> The bridge's request queue: agent threads ask, the host's main thread answers

The threading model of the bridge (robot_bridge.pl): an agent thread
never calls Python. It posts request(Id, Deadline, Op) on a message
queue of the host (`robot_bridge_requests` for robots' tables and
parameters, `robot_bridge_service` for the host's own service) and waits
for reply(Id, Reply) on a private queue that exists only during the
call, up to a deadline (bridge_call/5, bridge_service_call/3). The host's
main thread, between two control steps, takes the requests
(bridge_next_request/2, bridge_next_service_request/2) and answers each
(bridge_reply/2); a request whose caller gave up is dropped, a late
reply too. The serving thread may not wait for itself (a permission
error). What the requests are is robot_bridge.pl's; this module only
carries them.
*/

:- dynamic
    pending_/3,                 % Id, ReplyQueue, Who (robot(R) or service)
    server_/1,                  % ThreadId of the serving thread
    stopping_threads_/0.        % bridge_stop_threads/2 has aborted threads

:- create_prolog_flag(robot_bridge_timeout, 30.0, [type(float), keep(true)]).
:- create_prolog_flag(robot_service_timeout, 20.0, [type(float), keep(true)]).

request_queue(robot_bridge_requests).
service_queue(robot_bridge_service).

%!  check_timeout(+Seconds) is det.
%
%   @error domain_error(nonneg_number, Seconds) for a negative number.

check_timeout(Timeout) :-
    must_be(number, Timeout),
    (   Timeout >= 0
    ->  true
    ;   domain_error(nonneg_number, Timeout)
    ).

%!  bridge_call(+Robot, +Op, +PI, +Options, -Reply) is det.
%
%   Post request(Id, Deadline, Op) on the table request queue and wait for
%   reply(Id, Reply) on a private queue that exists only during the call.

bridge_call(Robot, Op, PI, Options, Reply) :-
    request_queue(RQ),
    host_call(RQ, robot(Robot), Op, PI, Options, Reply).

%!  bridge_service_call(+Op, -Reply, +Options) is det.
%
%   As a table request, but for the host's own service (the robot
%   process's `dfrl_robot(...)` requests, robot_service.pl): Op is posted
%   on a queue of its own, which the host serves in every state (also
%   while a sync robot serves no table request) with
%   bridge_next_service_request/2. Reply is what the host answered.
%   Options: timeout(Seconds), default the flag `robot_service_timeout`
%   (20 s).
%
%   @error existence_error(robot_service, host) if no host serves.
%   @error timeout_error(robot_service, host) if it did not answer in time.

bridge_service_call(Op, Reply, Options) :-
    must_be(nonvar, Op),
    must_be(list, Options),
    current_prolog_flag(robot_service_timeout, Default),
    option(timeout(Timeout), Options, Default),
    service_queue(SQ),
    host_call(SQ, service, Op, bridge_service_call/3, [timeout(Timeout)], Reply).

host_call(Queue, Who, Op, PI, Options, Reply) :-
    current_prolog_flag(robot_bridge_timeout, Default),
    option(timeout(Timeout), Options, Default),
    check_timeout(Timeout),
    thread_self(Me),
    (   server_(Me)
    ->  throw(error(permission_error(wait, bridge_reply, Me),
                    context(PI, 'the thread that serves bridge requests cannot wait for them')))
    ;   true
    ),
    flag(robot_bridge_request_id, Id0, Id0+1),
    Id is Id0 + 1,
    get_time(Now),
    Deadline is Now + Timeout,
    setup_call_cleanup(
        ( message_queue_create(Q),
          assertz(pending_(Id, Q, Who))
        ),
        ( catch(thread_send_message(Queue, request(Id, Deadline, Op)),
                error(existence_error(message_queue, _), _),
                ( gone_formal(Who, Gone), throw(error(Gone, context(PI, _))) )),
          (   thread_get_message(Q, reply(Id, Reply0), [timeout(Timeout)])
          ->  Reply = Reply0
          ;   format(atom(Msg), 'no reply within ~w s', [Timeout]),
              timeout_formal(Who, Formal),
              throw(error(Formal, context(PI, Msg)))
          )
        ),
        ( retractall(pending_(Id, _, _)),
          message_queue_destroy(Q)
        )).

gone_formal(robot(Robot), existence_error(robot, Robot)).
gone_formal(service, existence_error(robot_service, host)).

timeout_formal(robot(Robot), timeout_error(bridge, Robot)).
timeout_formal(service, timeout_error(robot_service, host)).

%!  bridge_next_request(-Request, +Timeout) is semidet.
%
%   Take the next request for the host, waiting at most Timeout seconds (0
%   polls). Request is request(Id, Op) with Op one of
%
%     - read_table(Robot)
%     - read_visits(Robot)
%     - read_table_and_visits(Robot)
%     - write_table(Robot, Shape, Data, Origin)  where Data is fts(String)
%       or text(String) (see robot_bridge:bridge_set_codec/1) and Origin
%       the list of the write's origin options (round(N), agent(A),
%       epoch(E), ...; see robot_bridge:write_table/3)
%     - read_params(Robot)
%     - write_params(Robot, Layout, Data, Origin)  Data and Origin as for
%       write_table
%     - anything else for the service queue (robot_service.pl)
%
%   Requests whose caller has already given up are dropped. Fails if no
%   request arrived in time. Answer every request with bridge_reply/2.

bridge_next_request(Request, Timeout) :-
    request_queue(RQ),
    next_from(RQ, Request, Timeout).

%!  bridge_next_service_request(-Request, +Timeout) is semidet.
%
%   As bridge_next_request/2 for the host's service queue (see
%   bridge_service_call/3): Request is request(Id, Op), answered with
%   bridge_reply/2.

bridge_next_service_request(Request, Timeout) :-
    service_queue(SQ),
    next_from(SQ, Request, Timeout).

next_from(Queue, Request, Timeout) :-
    check_timeout(Timeout),
    get_time(Now),
    Until is Now + Timeout,
    catch(next_request(Queue, Until, Request),
          error(existence_error(message_queue, _), _),
          fail).

next_request(RQ, Until, Request) :-
    get_time(Now),
    Wait is max(0, Until - Now),
    thread_get_message(RQ, request(Id, Deadline, Op), [timeout(Wait)]),
    (   pending_(Id, _, _),
        get_time(T),
        T =< Deadline
    ->  Request = request(Id, Op)
    ;   debug(robot_bridge, 'dropped expired request ~q', [Id]),
        next_request(RQ, Until, Request)
    ).

%!  bridge_reply(+Id, +Reply) is det.
%
%   Answer request Id. Reply is one of
%
%     - table(Shape, Data)  for read_table/read_visits, Data as in
%       bridge_next_request/2 (an fts string must come from pybridge's
%       encoder, see bridge_set_codec/1)
%     - tables(table(Shape, QData), table(Shape, VData)) for
%       read_table_and_visits
%     - params(Layout, Samples, Data)  for read_params
%     - ok                  for write_table and write_params
%     - error(Formal)       the caller throws error(Formal, Context)
%
%   A reply to a caller that has timed out is dropped silently.

bridge_reply(Id, Reply) :-
    must_be(integer, Id),
    must_be(nonvar, Reply),
    (   retract(pending_(Id, Q, _))
    ->  catch(thread_send_message(Q, reply(Id, Reply)),
              error(existence_error(message_queue, _), _),
              true)
    ;   debug(robot_bridge, 'late reply to ~q dropped', [Id])
    ).

%!  bridge_attach_server is det.
%
%   Declare the calling thread the one that serves requests (the Python
%   main thread). read_table/3 and friends called from that thread throw a
%   permission error instead of waiting forever for themselves.

bridge_attach_server :-
    thread_self(Me),
    retractall(stopping_threads_),
    ensure_request_queue,
    with_mutex(robot_bridge,
               ( retractall(server_(_)),
                 assertz(server_(Me)) )).

%!  bridge_detach_server is det.
%
%   Undo bridge_attach_server/0.

bridge_detach_server :-
    retractall(server_(_)).

%!  queue_shutdown is det.
%
%   Answer every waiting caller with existence_error(robot, Robot)
%   (existence_error(robot_service, host) for a service request), forget
%   the serving thread and destroy the request queues
%   (robot_bridge:bridge_shutdown/0 calls it, after it forgot the robots).

queue_shutdown :-
    with_mutex(robot_bridge,
               ( retractall(server_(_)),
                 forall(retract(pending_(Id, Q, Who)),
                        ( gone_formal(Who, Gone),
                          catch(thread_send_message(Q, reply(Id, error(Gone))),
                                _, true) )),
                 forall(( host_queue(HQ), is_message_queue(HQ) ),
                        message_queue_destroy(HQ)) )).

%!  bridge_stop_threads(+Timeout, -Remaining) is det.
%!  bridge_stop_threads(+Timeout, -Remaining, -Aborted) is det.
%
%   Abort every Prolog thread except the caller (and the system's `gc`
%   thread), wait at most Timeout seconds for them to stop and join those
%   that are joinable. A detached thread is never joined: in SWI-Prolog
%   9.0.4 thread_join/2 on a detached thread that is exiting can deadlock
%   the process (seen here, 1 in 50 closes under load; the loop in
%   tests/pybridge/stop_detached_script.pl hangs on such a join). A
%   detached thread frees itself; it is waited for like the others.
%   Remaining lists the threads still running (e.g. blocked in a system
%   call that a signal cannot interrupt because the host runs Prolog
%   without signal handling; the platform must stop those itself). Used by the host
%   before the interpreter exits, since live threads make the embedding's
%   cleanup unsafe. Aborted is the number of threads that were running.

bridge_stop_threads(Timeout, Remaining) :-
    bridge_stop_threads(Timeout, Remaining, _).

bridge_stop_threads(Timeout, Remaining, Aborted) :-
    check_timeout(Timeout),
    (   stopping_threads_
    ->  true
    ;   assertz(stopping_threads_)
    ),
    thread_self(Me),
    findall(T, other_thread(Me, T), Threads),
    include(running_thread, Threads, Running),
    length(Running, Aborted),
    forall(member(T, Running),
           catch(thread_signal(T, abort), _, true)),
    get_time(Now),
    Deadline is Now + Timeout,
    wait_stopped(Threads, Deadline),
    include(running_thread, Threads, Remaining),
    forall(( member(T, Threads),
             \+ memberchk(T, Remaining),
             \+ catch(thread_property(T, detached(true)), _, true)
           ),
           catch(thread_join(T, _), _, true)).

other_thread(Me, T) :-
    thread_property(T, status(_)),
    T \== Me,
    \+ thread_property(T, alias(gc)).

running_thread(T) :-
    catch(thread_property(T, status(running)), _, fail).

wait_stopped(Threads, Deadline) :-
    (   \+ ( member(T, Threads), running_thread(T) )
    ->  true
    ;   get_time(Now),
        Now >= Deadline
    ->  true
    ;   sleep(0.01),
        wait_stopped(Threads, Deadline)
    ).

%!  ensure_request_queue is det.
%
%   Create the host's request queues if they do not exist.

ensure_request_queue :-
    with_mutex(robot_bridge,
               forall(host_queue(Q),
                      (   is_message_queue(Q)
                      ->  true
                      ;   message_queue_create(_, [alias(Q)])
                      ))).

host_queue(Q) :- request_queue(Q).
host_queue(Q) :- service_queue(Q).

is_message_queue(Q) :-
    catch(message_queue_property(Q, size(_)), _, fail).
		 /*******************************
		 *           MESSAGES           *
		 *******************************/

:- multifile prolog:error_message//1, user:message_hook/3.

%   Threads aborted by bridge_stop_threads/2 (e.g. idle pool workers) would
%   each print "Thread running ... died on exception: Execution Aborted".
%   That is the expected end of them, so it is not printed.

user:message_hook(abnormal_thread_completion(_, exception(E)), warning, _) :-
    stopping_threads_,
    aborted(E).

aborted('$aborted').
aborted(unwind(abort)).

prolog:error_message(timeout_error(bridge, Robot)) -->
    [ 'No reply from the robot host for robot ~q (is its control loop serving requests?)'-[Robot] ].
prolog:error_message(timeout_error(robot_service, host)) -->
    [ 'No reply from the robot process (is its main thread serving requests?)' ].
prolog:error_message(existence_error(robot_service, host)) -->
    [ 'This process serves no robot service requests' ].
